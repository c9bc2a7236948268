"""Which role each route needs: the one place that decides.

A request is matched against the app's routes (the same matching the router does); the route's path template and
the method pick the rule. Reading (GET, HEAD, OPTIONS) needs the viewer role unless a rule says more; every other
method, and every websocket, needs a rule of its own here - a route without one needs the admin role, so a new
route is never open by accident. With no login configured the local user is an admin and passes every rule; a
remote-diagnostics link is a viewer.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

from fastapi import FastAPI
from fastapi.routing import iter_route_contexts
from starlette.routing import Match
from starlette.types import Scope

from drivebench.i18n import N_
from drivebench.services.users.principals import Role
from drivebench.web.lean_route import LeanHandler
from drivebench.web.root import route_path

SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
WEBSOCKET = "WS"


@dataclass(frozen=True)
class Rule:
    role: Role
    what: str
    """What the route does, as the start of a sentence: "Writing parameters" (needs the engineer role)."""


V, E, A = Role.VIEWER, Role.ENGINEER, Role.ADMIN
S = "/api/sessions/{session_id}"
N = S + "/nodes/{node_id}"
US = "/ui/sessions/{session_id}"
UN = US + "/nodes/{node_id}"


def _rules(role: Role, what: str, *routes: tuple[str, str]) -> dict[tuple[str, str], Rule]:
    return {route: Rule(role, what) for route in routes}


RULES: dict[tuple[str, str], Rule] = {
    # --- writes that only read or calculate: a viewer may ---------------------------------------------------
    **_rules(V, N_("Reading parameters"),
             ("POST", N + "/read-all"), ("POST", N + "/read-group"), ("POST", S + "/read-all"),
             ("POST", N + "/parameters:read"),
             ("POST", UN + "/parameters/{ref:path}/read"), ("POST", UN + "/read"), ("POST", UN + "/info/read")),
    **_rules(V, N_("Changing your own monitor view"),
             ("POST", S + "/monitor/pause"), ("POST", S + "/monitor/resume"), ("PUT", S + "/monitor/filter")),
    **_rules(V, N_("Using the calculators"),
             ("POST", "/api/tools/dip/{family}"), ("POST", "/api/tools/planner/check"),
             ("POST", "/api/tools/planner/compare"), ("POST", "/api/planned-networks/{network_id}/compare"),
             ("POST", "/ui/tools/dip"), ("POST", "/ui/tools/cable"), ("POST", "/ui/tools/planner"),
             ("POST", "/ui/tools/planner/check"), ("POST", "/ui/tools/planner/export"),
             ("POST", "/ui/tools/planner/import"), ("POST", "/ui/tools/planner/load/{network_id}"),
             ("POST", "/ui/tools/planner/compare")),
    **_rules(V, N_("Checking a line against its project"), ("POST", "/api/line-projects/{project_id}/boot-check"),
             ("POST", "/api/line-projects/concise-dcf/decode"), ("POST", "/api/line-projects/concise-dcf/from-dcf")),
    **_rules(V, N_("Comparing parameter sets"),
             ("POST", "/api/parameter-sets/compare"), ("POST", "/api/parameter-sets/{set_id}/preview"),
             ("POST", "/parameter-sets/compare"), ("POST", "/parameter-sets/{set_id}/preview")),
    **_rules(V, N_("Keeping your own drive commands alive"), ("POST", S + "/keepalive"),
             (WEBSOCKET, "/ws/sessions/{session_id}/keepalive")),  # keeps alive only what this browser started
    **_rules(V, N_("Signing in"), ("POST", "/api/auth/login"), ("GET", "/login"), ("POST", "/login")),
    **_rules(V, N_("Signing out"), ("POST", "/api/auth/logout"), ("POST", "/logout")),
    **_rules(V, N_("Changing your own password"), ("PUT", "/api/auth/password")),
    **_rules(V, N_("Managing your own API tokens"),
             ("GET", "/api/auth/tokens"), ("POST", "/api/auth/tokens"), ("DELETE", "/api/auth/tokens/{token_id}")),
    # --- engineer: anything that writes to a device or changes what others see ------------------------------
    # the server's metrics tell how the plant's buses and the tool are used: not for every viewer (a scraper uses the
    # metrics token instead, web/metrics_token.py)
    **_rules(E, N_("Reading the server's metrics"), ("GET", "/metrics")),
    **_rules(E, N_("Writing parameters"),
             ("PUT", N + "/parameters/{ref:path}"), ("POST", N + "/parameters:write"),
             ("POST", UN + "/parameters/{ref:path}/write")),
    **_rules(E, N_("Device commands (save, load defaults, reset)"),
             ("POST", N + "/commands/{command}"), ("POST", UN + "/commands/{command}")),
    **_rules(E, N_("NMT commands"), ("POST", S + "/nmt"), ("POST", N + "/nmt"), ("POST", US + "/nmt"),
             ("POST", UN + "/pdo/start-node")),
    **_rules(E, N_("Line addressing (LSS)"),
             ("POST", S + "/lss/fastscan"), ("POST", S + "/lss/assign"), ("POST", S + "/lss/switch-global"),
             ("POST", S + "/lss/activate-bit-timing"), ("POST", S + "/lss/reset-communication"),
             ("POST", S + "/lss/identify-non-configured"), ("POST", S + "/lss/identify-remote"),
             ("POST", S + "/lss/inquire")),
    **_rules(E, N_("Scanning the bus and adding or removing nodes"),
             ("POST", S + "/scan"), ("POST", S + "/nodes"), ("DELETE", N), ("POST", US + "/scan"),
             ("POST", US + "/nodes")),
    **_rules(E, N_("Changing heartbeat and node guarding"),
             ("PUT", N + "/heartbeat/producer"), ("PUT", N + "/heartbeat/consumers/{slot}"), ("PUT", N + "/guarding"),
             ("POST", UN + "/diagnostics/producer"), ("POST", UN + "/diagnostics/consumers/{slot}"),
             ("POST", UN + "/diagnostics/guarding")),
    **_rules(E, N_("Changing PDOs"), ("PUT", N + "/pdos/{direction}/{number}"),
             ("POST", UN + "/pdo/{direction}/{number}/apply")),
    **_rules(E, N_("Sending PDOs and SYNC"), ("POST", UN + "/pdo/rpdo/{number}/send"),
             ("POST", UN + "/pdo/rpdo/{number}/stop"), ("POST", UN + "/pdo/sync")),
    **_rules(E, N_("Controlling a drive"),
             ("POST", N + "/control/commands/{command}"), ("PUT", N + "/control/setpoint"),
             ("POST", N + "/control/jog"), ("PUT", N + "/control/mode"), ("POST", N + "/control/keepalive"),
             ("POST", N + "/control/move"), ("POST", N + "/control/home"), ("POST", N + "/control/cyclic"),
             ("DELETE", N + "/control/cyclic"),
             ("POST", N + "/control/sequences/{key}/runs"), ("POST", N + "/control/runs/{run_id}/next")),
    **_rules(E, N_("Resetting the monitor counters and recording"), ("POST", S + "/monitor/reset"),
             ("POST", S + "/monitor/recordings"), ("POST", S + "/monitor/recordings/stop"),
             ("POST", "/ui/monitor/{session_id}/recordings"), ("POST", "/ui/monitor/{session_id}/recordings/stop")),
    **_rules(E, N_("Starting and stopping scope recordings"), ("POST", S + "/scope/run"),
             ("POST", S + "/scope/run/stop")),
    **_rules(E, N_("Deleting scope recordings"), ("DELETE", "/api/scope/recordings/{recording_id}")),
    **_rules(E, N_("Changing device profiles"), ("POST", "/api/profiles"), ("DELETE", "/api/profiles/{profile_id}"),
             ("POST", "/ui/profiles"), ("POST", "/ui/profiles/{profile_id}/delete")),
    **_rules(E, N_("Creating, listing and revoking remote diagnostics links"), ("POST", "/api/share-links"),
             ("GET", "/api/share-links"), ("DELETE", "/api/share-links/{link_id}"), ("POST", "/ui/share-links"),
             ("POST", "/ui/share-links/{link_id}/revoke")),
    **_rules(E, N_("Saving planned networks"),
             ("POST", "/api/planned-networks"), ("POST", "/api/planned-networks/import"),
             ("PUT", "/api/planned-networks/{network_id}"), ("DELETE", "/api/planned-networks/{network_id}"),
             ("POST", "/ui/tools/planner/save"), ("POST", "/ui/tools/planner/delete/{network_id}")),
    **_rules(E, N_("Saving line projects"), ("POST", "/api/line-projects"), ("POST", "/api/line-projects/import"),
             ("DELETE", "/api/line-projects/{project_id}")),
    **_rules(E, N_("Downloading a concise DCF to a drive"),
             ("POST", "/api/line-projects/{project_id}/nodes/{node_id}/concise-dcf/download")),
    **_rules(E, N_("Changing parameter sets"),
             ("POST", "/api/parameter-sets/upload"), ("POST", "/api/parameter-sets/{set_id}/upload"),
             ("POST", "/api/parameter-sets/import"), ("PATCH", "/api/parameter-sets/{set_id}"),
             ("DELETE", "/api/parameter-sets/{set_id}"), ("POST", "/api/parameter-sets/{set_id}/copy"),
             ("POST", "/parameter-sets/upload"), ("POST", "/parameter-sets/{set_id}/upload"),
             ("POST", "/parameter-sets/import"), ("POST", "/parameter-sets/{set_id}/rename"),
             ("DELETE", "/parameter-sets/{set_id}"), ("POST", "/parameter-sets/{set_id}/copy")),
    **_rules(E, N_("Downloading parameter sets to a drive"),
             ("POST", "/api/parameter-sets/{set_id}/download"),
             ("POST", "/api/parameter-downloads/{download_id}/retry"),
             ("POST", "/api/parameter-downloads/{download_id}/rollback"), ("POST", "/parameter-sets/{set_id}/download"),
             ("POST", "/parameter-sets/downloads/{download_id}/{action}")),
    **_rules(E, N_("Commissioning a new line (wizard)"), ("POST", S + "/line-wizard"),
             ("PUT", S + "/line-wizard/{run_id}/assignments"), ("POST", S + "/line-wizard/{run_id}/firmware/{node_id}"),
             ("POST", S + "/line-wizard/{run_id}/steps/{step}")),
    **_rules(E, N_("Program download (firmware)"), ("POST", N + "/program/check"), ("POST", N + "/program/download"),
             ("POST", N + "/program/control/{command}")),
    **_rules(E, N_("Cancelling a job"), ("DELETE", "/api/jobs/{job_id}")),
    **_rules(E, N_("Releasing your write lease of a node"),
             ("DELETE", N + "/lease"),  # force=true: the route asks admin
             ("POST", UN + "/lease/release")),
    **_rules(E, N_("Injecting faults into simulated drives"), ("PUT", S + "/simulator/nodes/{node_id}/faults"),
             ("DELETE", S + "/simulator/nodes/{node_id}/faults"), ("PUT", S + "/simulator/lss/{serial}/faults")),
    # --- admin: sessions (adapters), their SDO settings, users and tokens -----------------------------------
    **_rules(A, N_("Opening and closing sessions (CAN adapters)"), ("POST", "/api/sessions"), ("DELETE", S),
             ("POST", "/ui/sessions"), ("POST", US + "/close")),
    **_rules(A, N_("Breaking another writer's lease"), ("POST", UN + "/lease/break")),
    **_rules(A, N_("Changing the SDO settings of a session"), ("PUT", S + "/sdo-settings"),
             ("POST", UN + "/sdo-settings")),
    **_rules(A, N_("Managing users"), ("GET", "/api/users"), ("POST", "/api/users"), ("GET", "/api/users/{name}"),
             ("PATCH", "/api/users/{name}"), ("PUT", "/api/users/{name}/password"), ("GET", "/users"),
             ("POST", "/ui/users"), ("POST", "/ui/users/{name}/disable"), ("POST", "/ui/users/{name}/enable"),
             ("POST", "/ui/users/{name}/role"), ("POST", "/ui/users/{name}/password")),
    **_rules(A, N_("Managing API tokens"), ("GET", "/api/tokens"), ("POST", "/api/tokens"),
             ("DELETE", "/api/tokens/{token_id}"), ("POST", "/ui/tokens"), ("POST", "/ui/tokens/{token_id}/revoke")),
    # --- websockets ----------------------------------------------------------------------------------------
    # The control socket only streams the drive's state; its messages keep alive a drive this panel holds, and
    # only an engineer's command makes a panel a holder.
    **_rules(V, N_("Watching a drive"), (WEBSOCKET, N.replace("/api/", "/ws/", 1) + "/control")),
    **_rules(V, N_("Watching"), (WEBSOCKET, "/ws/sessions/{session_id}/monitor"),
             (WEBSOCKET, "/ws/sessions/{session_id}/nodes"),
             (WEBSOCKET, "/ws/jobs/{job_id}"), (WEBSOCKET, "/ws/remote/{token}"),
             (WEBSOCKET, "/ws/sessions/{session_id}/nodes/{node_id}/process-data"),
             (WEBSOCKET, "/ws/sessions/{session_id}/scope")),
}

READING = Rule(V, N_("Reading"))
UNCLASSIFIED_WRITE = Rule(A, N_("This action (not yet given a role)"))
UNCLASSIFIED_WEBSOCKET = Rule(A, N_("This live connection (not yet given a role)"))

# Reached without signing in: the sign-in itself, static files, the health check, and the pages and stream of a
# remote-diagnostics link (which check the link's own token).
PUBLIC: frozenset[tuple[str, str]] = frozenset({
    ("GET", "/login"), ("POST", "/login"), ("POST", "/api/auth/login"), ("GET", "/api/health"),
    ("GET", "/remote/{token}"), ("GET", "/api/remote/{token}/content"), (WEBSOCKET, "/ws/remote/{token}"),
    ("GET", "/language/{code}"),
})
PUBLIC_PREFIXES = ("/static/",)


@dataclass(frozen=True)
class Decision:
    template: str | None
    """The matched route's path template (None: no route matches; the router answers 404 or 405)."""
    rule: Rule
    public: bool
    lean: LeanHandler | None = None
    """The route's lean answer for a GET (``lean_route``), which the gate tries before the router."""
    path_params: dict[str, Any] = field(default_factory=dict)
    """The path's parameters as the route converts them, where ``lean`` is set (the decision is then this path's)."""


def _method(scope: Scope) -> str:
    if scope["type"] == "websocket":
        return WEBSOCKET
    method = str(scope.get("method", "GET")).upper()
    return "GET" if method == "HEAD" else method


def rule_for(method: str, template: str) -> Rule:
    rule = RULES.get((method, template))
    if rule is not None:
        return rule
    if method == WEBSOCKET:
        return UNCLASSIFIED_WEBSOCKET
    return READING if method in SAFE_METHODS else UNCLASSIFIED_WRITE


@dataclass(frozen=True)
class RoutePolicy:
    """One route of the app with its decision per method, worked out at start-up (:func:`precompute`)."""

    route: object
    template: str
    by_method: dict[str, Decision]


_policies: weakref.WeakKeyDictionary[FastAPI, list[RoutePolicy]] = weakref.WeakKeyDictionary()


def _decision(method: str, template: str) -> Decision:
    return Decision(template, rule_for(method, template), public=(method, template) in PUBLIC)


def precompute(app: FastAPI) -> list[RoutePolicy]:
    """Every route of the app in the router's order with its decisions (routes are all added before it serves);
    done once per app, at start-up or by the first request."""
    policies = _policies.get(app)
    if policies is None:
        policies = []
        for route in routes_in_place(app.router.routes):
            template = getattr(route, "path", None)
            if template is None:
                continue
            methods = getattr(route, "methods", None) or ()
            by_method = {method: _decision(method, str(template)) for method in (*methods, WEBSOCKET)}
            policies.append(RoutePolicy(route, str(template), by_method))
        _policies[app] = policies
    return policies


def routes_in_place(routes: Iterable[Any]) -> Iterator[Any]:
    """The routes in the router's order, a router included without a prefix walked in place: its own routes match
    the same paths. FastAPI builds an included router's effective copies (each parameter's pydantic model again) on
    first use; asking it for them here (``iter_route_contexts``) cost a third of the start-up's CPU (issue 33), so
    only an include with a prefix is asked."""
    for route in routes:
        included = getattr(route, "original_router", None)
        if included is None:
            yield route
        elif getattr(getattr(route, "include_context", None), "prefix", None) == "":
            yield from routes_in_place(included.routes)
        else:
            yield from iter_route_contexts([route])


def build_effective_routes(app: FastAPI) -> None:
    """FastAPI's effective routes of every included router, which it otherwise builds on a router's first request
    (a worker thread runs this once the server listens: the first page does not wait for them)."""
    for _route in iter_route_contexts(app.router.routes):
        pass


DECISIONS_KEPT = 4096
"""Decisions remembered per app, by (scope type, method, path): a route matches on nothing else (no host routes)."""
_decisions: weakref.WeakKeyDictionary[FastAPI, dict[tuple[str, str, str], Decision]] = weakref.WeakKeyDictionary()


def decide(app: FastAPI, scope: Scope) -> Decision:
    """The rule of the route a request or websocket reaches: the precomputed decision of the route that matches,
    remembered per (type, method, path), so a repeated request costs one dictionary look-up."""
    key = (scope["type"], str(scope.get("method", "")), scope.get("path", ""))
    known = _decisions.get(app)
    if known is None:
        known = _decisions[app] = {}
    decision = known.get(key)
    if decision is None:
        decision = _match(app, scope)
        if len(known) >= DECISIONS_KEPT:
            known.clear()  # many distinct paths (parameter refs): start over rather than grow without bound
        known[key] = decision
    return decision


def _match(app: FastAPI, scope: Scope) -> Decision:
    method = _method(scope)
    path = route_path(scope)
    match_scope = {**scope, "method": "GET"} if scope.get("method") == "HEAD" else scope
    for policy in precompute(app):
        matched, child = policy.route.matches(match_scope)  # type: ignore[attr-defined]
        if matched is Match.FULL:
            if path.startswith(PUBLIC_PREFIXES) and method in SAFE_METHODS:
                return Decision(policy.template, READING, public=True)
            found = policy.by_method.get(method) or _decision(method, policy.template)
            lean = getattr(getattr(policy.route, "original_route", policy.route), "lean", None)
            if lean is not None and scope.get("method") == "GET":
                found = replace(found, lean=lean, path_params=dict(child["path_params"]))
            return found
    return Decision(None, READING, public=path.startswith(PUBLIC_PREFIXES))


def operations(app: FastAPI) -> Iterator[tuple[str, str, Rule]]:
    """Every (method, path template, rule) of the app, websockets with method ``WS`` (tests, OpenAPI)."""
    for policy in precompute(app):
        route, template = policy.route, policy.template
        methods = getattr(route, "methods", None)
        if methods is None:
            if type(getattr(route, "original_route", route)).__name__.endswith("WebSocketRoute"):
                yield WEBSOCKET, template, rule_for(WEBSOCKET, template)
            continue
        for method in sorted(methods - {"HEAD"}):
            yield method, template, rule_for(method, template)
