"""The sub-path DriveBench is served under behind a reverse proxy (``drivebench serve --root-path /drivebench``).

uvicorn puts the prefix into ``scope["root_path"]`` and in front of ``scope["path"]`` (the ASGI convention Starlette
routes by). The checks that decide by path (access rules, limits, the viewer's pages) read ``route_path``: the path
the router matches, the same with or without a prefix. What the server writes for a browser (links, redirects,
cookie paths) goes through ``under_root``.
"""

from __future__ import annotations

from starlette.types import Scope


def root_of(scope: Scope) -> str:
    """The prefix, without a trailing slash ("" when served at the top)."""
    return str(scope.get("root_path") or "").rstrip("/")


def route_path(scope: Scope) -> str:
    """The path without the prefix, as the router sees it (Starlette's rule: a path that does not start with the
    prefix is taken as it is)."""
    path = str(scope.get("path", ""))
    root = root_of(scope)
    if root and (path == root or path.startswith(root + "/")):
        return path[len(root):] or "/"
    return path


def under_root(scope: Scope, path: str) -> str:
    """A path of this server (``/login``) as the browser reaches it (``/drivebench/login``)."""
    return root_of(scope) + path


def cookie_path(scope: Scope) -> str:
    """The path the server's cookies are scoped to: the prefix, or ``/``."""
    return root_of(scope) or "/"
