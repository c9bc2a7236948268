"""One cookie's value from a request's ``Cookie`` header, without parsing the others (the gate asks per request)."""

from __future__ import annotations


def value(header: str | None, name: str) -> str | None:
    """The value of cookie ``name`` (quotes removed), or None when the header does not carry it or it is empty."""
    if not header or name not in header:
        return None
    for part in header.split(";"):
        key, _eq, found = part.strip().partition("=")
        if key == name and found:
            return found.strip('"')
    return None
