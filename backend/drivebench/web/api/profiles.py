"""Device profiles: list, JSON schema, one profile, upload (EDS/DCF/JSON), EDS download."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, UploadFile, status
from fastapi.responses import PlainTextResponse
from pydantic import BaseModel

from drivebench.device.eds_export import export_eds
from drivebench.device.loader import ProfileRegistry
from drivebench.device.profile import Profile
from drivebench.errors import ProfileError
from drivebench.web.deps import StateDep

router = APIRouter(prefix="/api/profiles", tags=["profiles"])


class ProfileSummary(BaseModel):
    id: str
    version: str
    family: str
    vendor: str
    product: str
    vendor_id: int | None
    product_code: int | None
    objects: int
    parameters: int
    builtin: bool


def summary(profile: Profile, registry: ProfileRegistry) -> ProfileSummary:
    return ProfileSummary(id=profile.id, version=profile.version, family=profile.family,
                          vendor=profile.identity.vendor_name, product=profile.identity.product_name,
                          vendor_id=profile.identity.vendor_id, product_code=profile.identity.product_code,
                          objects=len(profile.objects), parameters=len(profile.parameters),
                          builtin=registry.is_builtin(profile.id))


@router.get("", response_model=list[ProfileSummary])
async def list_profiles(state: StateDep) -> list[ProfileSummary]:
    return [summary(p, state.registry) for p in state.registry.all()]


@router.get("/schema")
async def profile_schema() -> dict[str, Any]:
    """The JSON schema of a profile file (device_profiles/*.json)."""
    return ProfileRegistry.json_schema()


@router.get("/{profile_id}", response_model=Profile)
async def get_profile(profile_id: str, state: StateDep) -> Profile:
    return state.registry.get(profile_id)


@router.get("/{profile_id}/eds", response_class=PlainTextResponse)
async def get_profile_eds(profile_id: str, state: StateDep) -> PlainTextResponse:
    profile = state.registry.get(profile_id)
    return PlainTextResponse(export_eds(profile), headers={
        "Content-Disposition": f'attachment; filename="{profile.id}.eds"'})


@router.post("", response_model=ProfileSummary, status_code=status.HTTP_201_CREATED)
async def upload_profile(file: UploadFile, state: StateDep) -> ProfileSummary:
    """Upload an EDS, DCF or JSON profile. A bad file is refused with file name, line and reason."""
    limit = state.registry.max_upload_bytes
    content = await file.read(limit + 1)
    if len(content) > limit:
        raise ProfileError(f"file is larger than {limit // 1024} KiB", source=file.filename or "upload")
    profile = state.registry.add_upload(file.filename or "upload", content)
    return summary(profile, state.registry)
