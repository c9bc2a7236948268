"""This server's own names: which ``Host`` and ``Origin`` are ours, and the address a link to it names.

A page of another site can point a name of its own at this machine (DNS rebinding: evil.example resolves to
127.0.0.1). Its requests then say ``Host: evil.example`` and ``Origin: http://evil.example``, which agree with each
other, so both are judged against one list instead: the loopback names, the configured ``allowed_hosts`` (``serve
--allowed-host``) and the IP address the client connected to (no other site's page has that origin).
"""

from __future__ import annotations

import ipaddress
import re

from starlette.datastructures import Headers
from starlette.types import Scope

from drivebench.config import settings
from drivebench.i18n import _

LOOPBACK_NAMES = frozenset({"127.0.0.1", "localhost", "[::1]"})
_NAME = r"(\[[0-9a-f:.]+\]|[a-z0-9_.-]+)"
_HOST = re.compile(_NAME + r"(?::(\d{1,5}))?")
_ORIGIN = re.compile(r"(?:https?|wss?)://" + _NAME + r"(?::(\d{1,5}))?")
_DEFAULT_PORTS = {"http": 80, "https": 443, "ws": 80, "wss": 443}


def canonical_name(name: str) -> str:
    """Lower case, an IPv6 address in brackets (as ``Host`` carries it)."""
    name = name.strip().lower()
    return f"[{name}]" if ":" in name and not name.startswith("[") else name


def configured_names() -> frozenset[str]:
    return frozenset(canonical_name(name) for name in settings.allowed_hosts)


def _own_address(scope: Scope) -> str | None:
    """The IP address the client connected to (the server's end of the connection), bracketed if IPv6."""
    server = scope.get("server")
    if not server:
        return None
    try:
        return canonical_name(str(ipaddress.ip_address(server[0])))
    except ValueError:
        return None


def _ours(name: str, scope: Scope) -> bool:
    return name in LOOPBACK_NAMES or name in configured_names() or name == _own_address(scope)


def host_refusal(scope: Scope, headers: Headers) -> str | None:
    """Why the request's ``Host`` is not a name of this server (None: it is)."""
    host = headers.get("host")
    if not host:
        return _("the request names no host (it has no Host header)")
    match = _HOST.fullmatch(host.strip().lower())
    if match is None or not _ours(match.group(1), scope):
        return _("the request is addressed to {host}, which is not a name of this server").format(host=repr(host[:100]))
    return None


def origin_refusal(scope: Scope, headers: Headers) -> str | None:
    """Why a request's ``Origin`` is not a page of this server (None: it is, or the request has none).

    A loopback origin must also be the very address the request went to (another port of 127.0.0.1 is another
    program's page); a configured name may differ in port (a reverse proxy forwards to the server's own port)."""
    origin = headers.get("origin")
    if origin is None:
        return None
    match = _ORIGIN.fullmatch(origin.strip().lower())
    if match is None or not _ours(match.group(1), scope):
        return _("it comes from a page of {origin}").format(origin=origin[:100])
    if match.group(1) in configured_names():
        return None
    host = _HOST.fullmatch(headers.get("host", "").strip().lower())
    scheme = origin.split(":", 1)[0].lower()
    origin_port = int(match.group(2) or _DEFAULT_PORTS.get(scheme, 0))
    host_port = int(host.group(2) or _DEFAULT_PORTS.get(scheme, 0)) if host else -1
    if host is None or host.group(1) != match.group(1) or host_port != origin_port:
        return _("it comes from a page of {origin}, another program on this machine").format(origin=origin[:100])
    return None


def public_base_url(scope: Scope) -> str:
    """``settings.public_url``, else the scheme and the address the server was reached at (its own socket, never
    the request's ``Host`` header)."""
    if settings.public_url:
        return settings.public_url.rstrip("/")
    scheme = str(scope.get("scheme", "http")).replace("ws", "http", 1)
    server = scope.get("server") or (settings.host, settings.port)
    host, port = canonical_name(str(server[0])), server[1]
    root = str(scope.get("root_path") or "").rstrip("/")  # the sub-path behind a proxy (serve --root-path)
    if port is None or port == _DEFAULT_PORTS.get(scheme):
        return f"{scheme}://{host}{root}"
    return f"{scheme}://{host}:{port}{root}"
