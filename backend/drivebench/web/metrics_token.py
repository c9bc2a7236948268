"""The metrics token: what a Prometheus scraper sends (``Authorization: Bearer <token>``, the token in
``DRIVEBENCH_METRICS_TOKEN_FILE``) to read ``/metrics`` without signing in. The gate honours it on that route only."""

from __future__ import annotations

import secrets

from starlette.datastructures import Headers

from drivebench.config import settings
from drivebench.services.users.principals import Principal, Role

METRICS_ROUTE = "/metrics"
SCRAPER = Principal("metrics scraper", Role.ENGINEER, via="metrics token")


def scraper(headers: Headers) -> Principal | None:
    """The scraper's principal when the request carries the metrics token (None: it does not, or none is set)."""
    path = settings.metrics_token_file
    given = headers.get("authorization", "")
    if path is None or not given.lower().startswith("bearer "):
        return None
    try:
        token = path.read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError):
        return None
    if token and secrets.compare_digest(given[7:].strip().encode(), token.encode()):
        return SCRAPER
    return None
