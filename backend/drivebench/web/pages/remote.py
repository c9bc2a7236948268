"""The Remote screen: share links for the engineer on site, and the read-only view a link opens."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Form, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response

from drivebench.services.monitoring import diagnostics
from drivebench.services.monitoring.remote_content import session_content
from drivebench.services.users.sharing import DEFAULT_SHOWS, SHOWS
from drivebench.web import access_policy
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.deps import StateDep
from drivebench.web.identity import principal_of
from drivebench.web.root import cookie_path, under_root
from drivebench.web.share_links import issued_link, share_link_public
from drivebench.web.templating import templates
from drivebench.web.viewer import COOKIE, require_engineer, viewer_token

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)
PAGE = "remote.html"


def health_context(state: Any, shows: tuple[str, ...] = SHOWS) -> dict[str, Any]:
    """Only what the heartbeat and EMCY consumers, the parameter service and the monitor already hold: viewers
    never cause bus traffic. ``shows``: what the link shows (the Remote page's preview shows everything)."""
    sessions = []
    for session in state.manager.list():
        nodes = diagnostics.network_health(session)
        history = {n.node_id: diagnostics.emcy_history(session, n.node_id)[:10] for n in nodes}
        sessions.append({"session": session, "nodes": nodes, "history": history,
                         "content": session_content(session, shows)})
    return {"sessions": sessions, "shows": shows}


def _links_context(request: Request, state: Any, **extra: Any) -> dict[str, Any]:
    """The active links (never their tokens) for those who may make them; None for everyone else."""
    may_list = principal_of(request).may(access_policy.rule_for("GET", "/api/share-links").role)
    links = [share_link_public(link) for link in state.share_links.active()] if may_list else None
    return {"active": "remote", "links": links, "all_shows": SHOWS, "default_shows": DEFAULT_SHOWS,
            **health_context(state), **extra}


@router.get("/remote", response_class=HTMLResponse)
async def remote_page(request: Request, state: StateDep) -> Response:
    token = viewer_token(request)
    if token is not None:
        return RedirectResponse(under_root(request.scope, f"/remote/{token}"), status_code=303)
    return templates.TemplateResponse(request, PAGE, _links_context(request, state))


@router.get("/remote/{token}", response_class=HTMLResponse)
async def remote_view(request: Request, state: StateDep, token: str) -> Response:
    link = state.share_links.check(token)
    context = {"active": "remote", "viewer": link, "token": token, **health_context(state, link.shows)}
    response = templates.TemplateResponse(request, "remote_view.html", context)
    remaining = max(int(link.expires - link.created), 60)
    response.set_cookie(COOKIE, token, max_age=remaining, httponly=True, samesite="strict",
                        secure=request.url.scheme == "https", path=cookie_path(request.scope))
    return response


@router.post("/ui/share-links", response_class=HTMLResponse)
async def create_link(request: Request, state: StateDep, ttl_minutes: int = Form(60),
                      label: str = Form(""), shows: list[str] = Form(default_factory=list)) -> Response:
    require_engineer(request)
    ttl_s = min(max(ttl_minutes, 1), 7 * 24 * 60) * 60
    created = issued_link(state.share_links.create(ttl_s, label, shows), request)
    return templates.TemplateResponse(request, PAGE, _links_context(request, state, created=created),
                                      block_name="links")


@router.post("/ui/share-links/{link_id}/revoke", response_class=HTMLResponse)
async def revoke_link(request: Request, state: StateDep, link_id: str) -> Response:
    require_engineer(request)
    state.share_links.revoke(link_id)
    return templates.TemplateResponse(request, PAGE, _links_context(request, state), block_name="links")
