"""The ``abort_texts`` section of a device profile: the manual's own wording of SDO abort codes.

A user sees the device manual's text next to an aborted read or write where the profile has one, else CiA 301's
(:mod:`drivebench.protocol.abort_codes`). Codes are written ``"0x06090030"`` in the files.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PlainSerializer, WithJsonSchema

AbortCode = Annotated[int, BeforeValidator(lambda v: int(v, 0) if isinstance(v, str) else v),
                      Field(ge=0, le=0xFFFFFFFF), PlainSerializer(lambda v: f"0x{v:08X}", return_type=str),
                      WithJsonSchema({"type": "string", "pattern": r"^0[xX][0-9a-fA-F]{8}$"})]


class AbortTexts(BaseModel):
    """The manual's abort table: code -> text (verbatim, or with the CiA 301 meaning where the manual misleads)."""

    model_config = ConfigDict(extra="forbid")

    source: str | None = None
    """The manual's chapter and what this table adds to or changes in its wording."""
    texts: dict[AbortCode, str] = Field(default_factory=dict)
