"""Share links for the remote diagnostics view: an unguessable token that expires and can be revoked.

A token grants the *viewer* scope only: read what DriveBench already holds and watch, never write, NMT or PDO, and
never make the drives answer (enforced by the web layer for every request that carries it). The token is shown
once, when the link is made; the server keeps only its SHA-256 (the token is random, so a fast hash is enough), an
id to name it and its first characters as a hint. Links live in memory: a server restart revokes them all.
"""

from __future__ import annotations

import hashlib
import secrets
import threading
import time
from dataclasses import dataclass

from drivebench.errors import NotAuthenticated, NotFound

TOKEN_PREFIX = "dbv_"
MAX_TTL_S = 7 * 24 * 3600
HINT_LENGTH = 8


@dataclass(frozen=True)
class ShareLink:
    id: str
    hint: str
    """The token's first characters (``dbv_AbCd``), to tell links apart; never enough to use one."""
    label: str
    created: float
    expires: float

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
    def __init__(self) -> None:
        self._links: dict[str, ShareLink] = {}  # by the token's digest
        self._lock = threading.Lock()

    def create(self, ttl_s: float, label: str = "") -> IssuedLink:
        ttl_s = min(max(ttl_s, 60.0), MAX_TTL_S)
        now = time.time()
        token = TOKEN_PREFIX + secrets.token_urlsafe(24)
        link = ShareLink(secrets.token_hex(6), token[:HINT_LENGTH], label.strip()[:80], now, now + ttl_s)
        with self._lock:
            self._links = {d: lk for d, lk in self._links.items() if not lk.expired(now)}
            self._links[_digest(token)] = link
        return IssuedLink(link, token)

    def check(self, token: str) -> ShareLink:
        """The link for ``token``; NotAuthenticated when it is unknown, revoked or expired."""
        with self._lock:
            link = self._links.get(_digest(token))
        if link is None:
            raise NotAuthenticated("This share link is not valid (it was revoked, or the server restarted).",
                                   hint="Ask the engineer on site for a new link.")
        if link.expired():
            expired_at = time.strftime("%Y-%m-%d %H:%M", time.localtime(link.expires))
            raise NotAuthenticated(f"This share link expired at {expired_at}.",
                                   hint="Ask the engineer on site for a new link.")
        return link

    def revoke(self, id_or_token: str) -> None:
        """Revoke the link with this id (as listed), or the link of this token."""
        with self._lock:
            digest = _digest(id_or_token)
            if digest not in self._links:
                digest = next((d for d, lk in self._links.items() if lk.id == id_or_token), "")
            if self._links.pop(digest, None) is None:
                raise NotFound("There is no active share link with that id or token.")

    def active(self) -> list[ShareLink]:
        now = time.time()
        with self._lock:
            return sorted((lk for lk in self._links.values() if not lk.expired(now)), key=lambda lk: lk.created)
