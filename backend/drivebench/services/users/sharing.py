"""Share links for the remote diagnostics view: an unguessable token that expires and can be revoked.

A token grants the *viewer* scope only: read what DriveBench already holds and watch, never write, NMT or PDO, and
never make the drives answer (enforced by the web layer for every request that carries it). The token is shown
once, when the link is made; the server keeps only its SHA-256 (the token is random, so a fast hash is enough), an
id to name it and its first characters as a hint, in the database: every server of the database honours a link
made on any of them, and a restart keeps them.
"""

from __future__ import annotations

import hashlib
import secrets
import time
from collections.abc import Iterable
from dataclasses import dataclass

from sqlalchemy import delete, or_, select

from drivebench.errors import InvalidValue, NotAuthenticated, NotFound
from drivebench.i18n import N_, _
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import ShareLinkRow

TOKEN_PREFIX = "dbv_"
MAX_TTL_S = 7 * 24 * 3600
HINT_LENGTH = 8
SHOWS = ("health", "faults", "emcy", "parameters", "bus", "scope")
"""What a link can show, chosen per link: node health; each drive's present fault in words and its fault history;
the last emergency telegrams; the diagnosis parameters as last read (with their age); bus load and the monitor's
counters; the oscilloscope (watch a running recording, open and export stored ones: never start, stop or delete)."""
DEFAULT_SHOWS = ("health", "faults")


@dataclass(frozen=True)
class ShareLink:
    id: str
    hint: str
    """The token's first characters (``dbv_AbCd``), to tell links apart; never enough to use one."""
    label: str
    created: float
    expires: float
    shows: tuple[str, ...] = DEFAULT_SHOWS

    def expired(self, now: float | None = None) -> bool:
        return (now or time.time()) >= self.expires


@dataclass(frozen=True)
class IssuedLink:
    link: ShareLink
    token: str
    """The token itself: in the answer that made the link, never stored."""


def _digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


class ShareLinks:
    """The links in the database (``share_link``): every server of the database honours them, a restart keeps
    them, a revocation on one server holds on all."""

    def __init__(self, url: str | None = None) -> None:
        self.url = url

    def create(self, ttl_s: float, label: str = "", shows: Iterable[str] = DEFAULT_SHOWS) -> IssuedLink:
        ttl_s = min(max(ttl_s, 60.0), MAX_TTL_S)
        now = time.time()
        token = TOKEN_PREFIX + secrets.token_urlsafe(24)
        link = ShareLink(secrets.token_hex(6), token[:HINT_LENGTH], label.strip()[:80], now, now + ttl_s,
                         chosen_shows(shows))
        with transaction(self.url) as db:
            db.execute(delete(ShareLinkRow).where(ShareLinkRow.expires <= now))
            db.add(ShareLinkRow(id=link.id, token_hash=_digest(token), hint=link.hint, label=link.label,
                                created=link.created, expires=link.expires, shows=",".join(link.shows)))
        return IssuedLink(link, token)

    def check(self, token: str) -> ShareLink:
        """The link for ``token``; NotAuthenticated when it is unknown, revoked or expired."""
        with transaction(self.url) as db:
            row = db.scalar(select(ShareLinkRow).where(ShareLinkRow.token_hash == _digest(token)))
            link = _link(row) if row is not None else None
        if link is None:
            raise NotAuthenticated(_("This share link is not valid (it was revoked, or it expired long ago)."),
                                   hint=N_("Ask the engineer on site for a new link."))
        if link.expired():
            expired_at = time.strftime("%Y-%m-%d %H:%M", time.localtime(link.expires))
            raise NotAuthenticated(_("This share link expired at {moment}.").format(moment=expired_at),
                                   hint=N_("Ask the engineer on site for a new link."))
        return link

    def revoke(self, id_or_token: str) -> None:
        """Revoke the link with this id (as listed), or the link of this token."""
        with transaction(self.url) as db:
            gone = db.execute(delete(ShareLinkRow).where(or_(ShareLinkRow.token_hash == _digest(id_or_token),
                                                              ShareLinkRow.id == id_or_token)))
            if not gone.rowcount:  # type: ignore[attr-defined]
                raise NotFound(_("There is no active share link with that id or token."))

    def active(self) -> list[ShareLink]:
        with transaction(self.url) as db:
            rows = db.scalars(select(ShareLinkRow).where(ShareLinkRow.expires > time.time())
                              .order_by(ShareLinkRow.created))
            return [_link(row) for row in rows]


def chosen_shows(shows: Iterable[str]) -> tuple[str, ...]:
    """The chosen parts in ``SHOWS`` order; an unknown name is refused in words, nothing chosen at all too."""
    wanted = {name.strip() for name in shows if name.strip()}
    unknown = sorted(wanted - set(SHOWS))
    if unknown:
        raise InvalidValue(_("A share link cannot show {names}: it shows {known}.").format(
            names=", ".join(unknown), known=", ".join(SHOWS)))
    if not wanted:
        raise InvalidValue(_("Choose at least one thing the share link shows."))
    return tuple(name for name in SHOWS if name in wanted)


def _link(row: ShareLinkRow) -> ShareLink:
    shows = tuple(name for name in SHOWS if name in row.shows.split(","))
    return ShareLink(row.id, row.hint, row.label, row.created, row.expires, shows)
