"""(Re)write ``device_profiles/eds/<profile id>.eds`` from every shipped JSON profile.

Run ``python -m drivebench.device.formats.build_eds`` after editing a profile;
``tests/device/test_shipped_eds.py`` fails while a shipped EDS differs from what its JSON profile exports.
"""

from __future__ import annotations

import sys
from pathlib import Path

from drivebench.config import settings
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.profiles.loader import load_profile_file
from drivebench.device.profiles.profile import Profile

EDS_SUBDIR = "eds"


def shipped_profiles(profiles_dir: Path | None = None) -> list[Profile]:
    """Every JSON profile in the built-in directory, by file name. A file that does not load raises ProfileError."""
    directory = profiles_dir or settings.profiles_dir
    return [load_profile_file(path.read_bytes(), path.name) for path in sorted(directory.glob("*.json"))]


def eds_path(profile: Profile, profiles_dir: Path | None = None) -> Path:
    return (profiles_dir or settings.profiles_dir) / EDS_SUBDIR / f"{profile.id}.eds"


def build(profiles_dir: Path | None = None) -> list[Path]:
    """Write one EDS per shipped JSON profile; returns the files that changed."""
    changed: list[Path] = []
    for profile in shipped_profiles(profiles_dir):
        path = eds_path(profile, profiles_dir)
        text = export_eds(profile)
        if path.is_file() and path.read_text(encoding="utf-8") == text:
            continue
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8", newline="\n")
        changed.append(path)
    return changed


def main() -> int:
    changed = build()
    for path in changed:
        print(f"wrote {path}")
    if not changed:
        print("all shipped EDS files are up to date")
    return 0


if __name__ == "__main__":
    sys.exit(main())
