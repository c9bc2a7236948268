"""Who is acting: a principal (a name and a role). Roles are ordered: each one may do what the lower ones may."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

from drivebench.i18n import _


class Role(IntEnum):
    VIEWER = 1  # read, watch, remote diagnostics
    ENGINEER = 2  # write parameters, PDOs, NMT, device commands
    ADMIN = 3  # users, sessions, adapters

    @property
    def label(self) -> str:
        return self.name.lower()

    @classmethod
    def parse(cls, text: str) -> Role:
        try:
            return cls[text.strip().upper()]
        except KeyError:
            raise ValueError(_("unknown role {role}: choose viewer, engineer or admin").format(
                role=repr(text))) from None


@dataclass(frozen=True)
class Principal:
    name: str
    role: Role
    via: str = "local"  # local (no login configured), login (cookie session), token (API token), link (share link)
    token_id: int | None = field(default=None, compare=False)
    """The API token acting (via ``token``): a token it makes ends with it."""

    def may(self, role: Role) -> bool:
        return self.role >= role
