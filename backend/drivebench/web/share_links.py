"""How a remote-diagnostics share link is shown: listed (without its token) and once, when made, with token and
address. Shared by the diagnostics API and the remote page."""

from __future__ import annotations

from pydantic import BaseModel
from starlette.requests import HTTPConnection

from drivebench.services.users.sharing import IssuedLink, ShareLink
from drivebench.web.origins import public_base_url


class ShareLinkPublic(BaseModel):
    id: str
    """Names the link to revoke it (``DELETE /api/share-links/{id}``)."""
    hint: str
    """The token's first characters; the token itself is shown once, when the link is made."""
    label: str
    created: float
    expires: float
    shows: list[str]


class IssuedShareLink(ShareLinkPublic):
    token: str
    url: str
    """``public_url`` (``serve --public-url``) or the server's own address + ``/remote/{token}``."""


def share_link_public(link: ShareLink) -> ShareLinkPublic:
    return ShareLinkPublic(id=link.id, hint=link.hint, label=link.label, created=link.created, expires=link.expires,
                           shows=list(link.shows))


def issued_link(issued: IssuedLink, conn: HTTPConnection) -> IssuedShareLink:
    url = f"{public_base_url(conn.scope)}/remote/{issued.token}"
    return IssuedShareLink(**share_link_public(issued.link).model_dump(), token=issued.token, url=url)
