"""Share links for the remote diagnostics view: an unguessable token that expires and can be revoked.

A token grants the *viewer* scope only: read and watch, never write, NMT or PDO (enforced by the web layer for
every request that carries it). Links live in memory: a server restart revokes them all.
"""

from __future__ import annotations

import secrets
import threading
import time
from dataclasses import dataclass

from drivebench.errors import NotAuthenticated, NotFound

TOKEN_PREFIX = "dbv_"
MAX_TTL_S = 7 * 24 * 3600


@dataclass(frozen=True)
class ShareLink:
    token: str
    label: str
    created: float
    expires: float

    def expired(self, now: float | None = None) -> bool:
        return (now or time.time()) >= self.expires


class ShareLinks:
    def __init__(self) -> None:
        self._links: dict[str, ShareLink] = {}
        self._lock = threading.Lock()

    def create(self, ttl_s: float, label: str = "") -> ShareLink:
        ttl_s = min(max(ttl_s, 60.0), MAX_TTL_S)
        now = time.time()
        link = ShareLink(TOKEN_PREFIX + secrets.token_urlsafe(24), label.strip()[:80], now, now + ttl_s)
        with self._lock:
            self._links = {t: lk for t, lk in self._links.items() if not lk.expired(now)}
            self._links[link.token] = link
        return link

    def check(self, token: str) -> ShareLink:
        """The link for ``token``; NotAuthenticated when it is unknown, revoked or expired."""
        with self._lock:
            link = self._links.get(token)
        if link is None:
            raise NotAuthenticated("This share link is not valid (it was revoked, or the server restarted).",
                                   hint="Ask the engineer on site for a new link.")
        if link.expired():
            expired_at = time.strftime("%Y-%m-%d %H:%M", time.localtime(link.expires))
            raise NotAuthenticated(f"This share link expired at {expired_at}.",
                                   hint="Ask the engineer on site for a new link.")
        return link

    def revoke(self, token: str) -> None:
        with self._lock:
            if self._links.pop(token, None) is None:
                raise NotFound("No such share link")

    def active(self) -> list[ShareLink]:
        now = time.time()
        with self._lock:
            return sorted((lk for lk in self._links.values() if not lk.expired(now)), key=lambda lk: lk.created)
