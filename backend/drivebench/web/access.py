"""Access control for every request and websocket: who is it, may they, and did the request come from our page.

* Every request and websocket must be addressed to a name of this server (``Host``: loopback, ``--allowed-host``;
  ``web/origins``), or it is refused with 400 before anything else: a rebound DNS name reaches nothing.
* Another web site's page may never change anything here, login or not: an unsafe request or a websocket handshake
  whose ``Origin`` is not a name of this server (or whose ``Sec-Fetch-Site`` says another site) is refused.
  Requests without those headers (curl, scripts) pass.
* Without an enabled admin nobody signs in: the server then serves only clients on this machine (loopback, or no
  network address at all); another machine gets 403 (``/api/health`` and the other public routes excepted).
* Once authentication is configured (an enabled admin exists, ``services.accounts``) everyone signs in: a signed
  session cookie (HttpOnly, SameSite=Strict, Secure over https) or ``Authorization: Bearer dbt_…``. Without it an
  API request gets 401, a page the sign-in form.
* The role a route needs comes from ``access_policy``; too low a role gets 403 with the reason in words.
* A cookie session's unsafe requests carry its CSRF token (header ``X-CSRF-Token``, or a form field
  ``csrf_token``); token requests need none (a browser never sends a bearer token by itself).

The principal goes into ``scope["state"]["principal"]`` (``identity.principal_of``) and, with login configured,
into the write context of the request (``web/safety.write_context``: who the audit log names).
"""

from __future__ import annotations

import ipaddress
import re
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import quote

import anyio.to_thread
from fastapi import FastAPI
from itsdangerous import BadSignature, URLSafeTimedSerializer
from sqlalchemy.exc import InterfaceError, OperationalError
from starlette.datastructures import Headers
from starlette.requests import HTTPConnection, Request
from starlette.responses import HTMLResponse, JSONResponse, PlainTextResponse, RedirectResponse, Response
from starlette.types import Message, Receive, Scope, Send

from drivebench.config import settings
from drivebench.errors import AccessDenied, DriveBenchError, NotAuthenticated, UnknownHostName
from drivebench.i18n import N_, _
from drivebench.services.users import accounts
from drivebench.services.users.principals import Principal, Role
from drivebench.services.users.sharing import ShareLinks
from drivebench.web import access_policy, cookies, metrics_token, origins
from drivebench.web.identity import principal_of
from drivebench.web.limits import BATCH_PATHS
from drivebench.web.metrics_token import METRICS_ROUTE
from drivebench.web.problems import error_fragment, error_page, problem_body, wants_page
from drivebench.web.root import cookie_path, route_path, under_root
from drivebench.web.secret_file import kept_key

SESSION_COOKIE = "drivebench_session"
CSRF_HEADER = "x-csrf-token"
CSRF_FIELD = "csrf_token"
SAFE_METHODS = access_policy.SAFE_METHODS


# --- the key that signs the session cookies --------------------------------------------------------------------
def secret_key() -> str:
    """``DRIVEBENCH_SECRET_KEY``, else a random key made once and kept (mode 0600) in ``settings.secret_key_file``
    (written atomically; an empty file is refused in words: web/secret_file.py)."""
    if settings.secret_key:
        return settings.secret_key
    return kept_key(Path(settings.secret_key_file))


# --- sessions ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SignedIn:
    name: str
    stamp: str
    csrf: str
    sid: str


class Sessions:
    """Signed session cookies; a signed-out session is refused until its cookie would have expired, by every server
    of the database (``accounts.sign_out_session``). A web app holds one (``web/state.AppState.cookie_sessions``):
    what it keeps in memory is only the signer of the current key."""

    def __init__(self) -> None:
        self._serializer: tuple[str, URLSafeTimedSerializer] | None = None

    def _codec(self) -> URLSafeTimedSerializer:
        key = secret_key()
        if self._serializer is None or self._serializer[0] != key:
            self._serializer = (key, URLSafeTimedSerializer(key, salt="drivebench-session"))
        return self._serializer[1]

    def issue(self, user: accounts.User) -> tuple[str, SignedIn]:
        signed_in = SignedIn(user.name, user.stamp, secrets.token_urlsafe(32), secrets.token_urlsafe(16))
        value = self._codec().dumps({"u": signed_in.name, "s": signed_in.stamp, "c": signed_in.csrf,
                                     "i": signed_in.sid})
        return value, signed_in

    def load(self, value: str) -> SignedIn | None:
        """The session of a cookie: None when it is forged, expired or signed out (this asks the database)."""
        try:
            data = self._codec().loads(value, max_age=settings.session_max_age_s)
            signed_in = SignedIn(str(data["u"]), str(data["s"]), str(data["c"]), str(data["i"]))
        except (BadSignature, KeyError, TypeError):
            return None
        return None if accounts.session_signed_out(signed_in.sid) else signed_in

    def sign_out(self, signed_in: SignedIn) -> None:
        accounts.sign_out_session(signed_in.sid, settings.session_max_age_s)



def set_session_cookie(response: Response, conn: HTTPConnection, value: str) -> None:
    response.set_cookie(SESSION_COOKIE, value, max_age=settings.session_max_age_s, httponly=True, samesite="strict",
                        secure=conn.url.scheme in ("https", "wss"), path=cookie_path(conn.scope))


def clear_session_cookie(response: Response, conn: HTTPConnection) -> None:
    response.delete_cookie(SESSION_COOKIE, httponly=True, samesite="strict", secure=conn.url.scheme == "https",
                           path=cookie_path(conn.scope))


@dataclass(frozen=True)
class AccessView:
    """What the templates show: who is signed in, whether signing in is on, the CSRF token of the session."""

    principal: Principal
    login: bool
    csrf: str | None
    session: SignedIn | None = None

    def may(self, role: str) -> bool:
        return self.principal.may(Role.parse(role))

    def refused_rules(self) -> list[dict[str, str]]:
        """The rules this principal does not meet, for the page to grey out their controls (the server decides)."""
        return [{"method": method, "pattern": _pattern(template), "role": rule.role.label, "what": rule.what}
                for (method, template), rule in access_policy.RULES.items()
                if method != access_policy.WEBSOCKET and not self.principal.may(rule.role)]


def _pattern(template: str) -> str:
    """``/a/{id}/b/{ref:path}`` as a JavaScript regular expression for the page."""
    parts = re.split(r"(\{[^}]+\})", template)
    return "^" + "".join(("(.+)" if part.endswith(":path}") else "([^/]+)") if part.startswith("{")
                         else re.escape(part) for part in parts) + "$"


def access_of(conn: HTTPConnection) -> AccessView | None:
    view = conn.scope.get("state", {}).get("access")
    return view if isinstance(view, AccessView) else None


# --- the middleware -----------------------------------------------------------------------------------------------
def cross_site(scope: Scope, headers: Headers) -> str | None:
    """Why an unsafe request or a websocket handshake comes from another site's page (None: it does not)."""
    if scope["type"] == "http" and str(scope.get("method", "GET")).upper() in SAFE_METHODS:
        return None
    site = headers.get("sec-fetch-site")
    if site and site not in ("same-origin", "none"):
        return _("the browser says it comes from a {site} page").format(site=site)
    return origins.origin_refusal(scope, headers)


def _denied_words(principal: Principal, rule: access_policy.Rule) -> str:
    who = (_("you are using a remote diagnostics link (viewer)") if principal.via == "link"
           else _("you are signed in as {name} ({role})").format(name=principal.name, role=principal.role.label))
    return _("{what} needs the {role} role; {who}.").format(what=_(rule.what), role=rule.role.label, who=who)


@dataclass(frozen=True)
class SignIns:
    """What a request's sign-in is checked against: the app's accounts and its cookie sessions."""

    accounts: accounts.Accounts
    sessions: Sessions


async def admitted(scope: Scope, receive: Receive, send: Send, headers: Headers, decision: access_policy.Decision,
                   sign_ins: SignIns) -> tuple[Receive, str | None] | None:
    """Host, origin, sign-in, role and CSRF of a request or websocket (``web/gate.py`` calls it once per request).
    None: refused, the answer is sent. Else the receive to pass on (a form read for its CSRF token is replayed) and
    the name the audit log gives the request's writes (None: the local user, no login configured)."""
    if (wrong_host := origins.host_refusal(scope, headers)) is not None:
        await _refuse_host(scope, receive, send, wrong_host)
        return None
    reason = cross_site(scope, headers)
    if reason is not None:
        await _refuse(scope, receive, send, AccessDenied(
            _("Refused: {reason}. Another web site may not change anything on DriveBench or open its live "
              "connections.").format(reason=reason), hint=N_("Open DriveBench itself and do it there.")))
        return None
    state = scope.setdefault("state", {})
    try:
        configured = sign_ins.accounts.authentication_configured()
    except (OperationalError, InterfaceError):  # the database is down: the gate answers 503, a public route is served
        if not decision.public:
            raise
        state["access"] = AccessView(Principal("", Role.VIEWER, via="none"), True, None, None)
        return receive, None
    session: SignedIn | None = None
    principal: Principal | None = None
    try:
        if state.get("viewer") is not None:  # a remote-diagnostics link (the gate checked its token)
            principal = principal_of(HTTPConnection(scope))
        elif decision.template == METRICS_ROUTE and (scraping := metrics_token.scraper(headers)) is not None:
            principal = scraping  # on this route only: the metrics token grants nothing else
        elif configured:
            principal, session = await _authenticate(headers, sign_ins)
    except NotAuthenticated as exc:
        if not decision.public:
            await _refuse(scope, receive, send, exc)
            return None
    if principal is None and configured and not decision.public:
        await _refuse(scope, receive, send, NotAuthenticated(
            _("Sign in first: this DriveBench server asks everyone to sign in."),
            hint=_("API clients send `Authorization: Bearer dbt_…` (an API token from the Users page).")))
        return None
    if principal is None and not configured:
        if not decision.public and (remote := _remote_address(scope)) is not None:
            await _refuse(scope, receive, send, AccessDenied(
                _("Refused: this DriveBench server has no enabled admin, so nobody signs in and it serves only "
                  "from this machine; {address} is another one.").format(address=remote),
                hint=_("Create an admin on the server (`drivebench users add admin --role admin`); then everyone "
                       "signs in, from anywhere.")))
            return None
        principal = principal_of(HTTPConnection(scope))  # the local user: an admin
    if principal is not None and not decision.public and not principal.may(decision.rule.role):
        await _refuse(scope, receive, send, AccessDenied(_denied_words(principal, decision.rule),
                                                         hint=_("Ask an admin for the role.")))
        return None
    if (session is not None and not decision.public and scope["type"] == "http"
            and scope["method"] not in SAFE_METHODS):
        token, receive = await _csrf_token(scope, receive, headers)
        if token is None or not secrets.compare_digest(token, session.csrf):
            await _refuse(scope, receive, send, AccessDenied(
                _("The request lacks this page's security token (CSRF), so it was not carried out."),
                hint=_("Reload the page and try again.")))
            return None
    if principal is not None:
        state["principal"] = principal
    state["access"] = AccessView(principal or Principal("", Role.VIEWER, via="none"), configured,
                                 session.csrf if session else None, session)
    if configured and principal is not None:
        # Whatever a client claims in X-DriveBench-User, the audit log names who signed in.
        scope["headers"] = [(k, v) for k, v in scope["headers"] if k.lower() != b"x-drivebench-user"]
        scope["headers"].append((b"x-drivebench-user", principal.name.encode()))
        return receive, principal.name
    return receive, None


async def still_admitted(scope: Scope, headers: Headers, decision: access_policy.Decision, links: ShareLinks,
                         sign_ins: SignIns) -> DriveBenchError | None:
    """Why a live connection admitted at its handshake may not stay open now (None: it may), as its handshake
    would be answered now: the share link still valid, the cookie session or API token still signed in (read from
    the database, as every request reads it: a change made by another server counts too), the route's role still
    held and the role not lowered since the handshake (``web/live_access`` asks it every second)."""
    state = scope.get("state", {})
    if (link_token := state.get("viewer_token")) is not None:
        try:
            await anyio.to_thread.run_sync(links.check, link_token)
        except DriveBenchError as exc:
            return exc
        return None
    if decision.public or not sign_ins.accounts.authentication_configured():  # a public socket checks its own link
        return None
    opened = state.get("principal")
    try:
        principal, _session = await _authenticate(headers, sign_ins)
    except NotAuthenticated as exc:
        return exc
    if principal is None:
        return NotAuthenticated(_("Your sign-in has ended (signed out, disabled, a new password or role): this "
                                  "live connection is closed."), hint=N_("Sign in again."))
    if not principal.may(decision.rule.role):
        return AccessDenied(_denied_words(principal, decision.rule), hint=_("Ask an admin for the role."))
    if isinstance(opened, Principal) and principal.role < opened.role:
        return AccessDenied(_("Your role was lowered to {role}: this live connection, opened as {before}, is "
                              "closed.").format(role=principal.role.label, before=opened.role.label),
                            hint=N_("Open it again."))
    return None


def _remote_address(scope: Scope) -> str | None:
    """The client's address when it is another machine's (None: loopback, or no network address at all: a Unix
    socket, an in-process client). Behind a trusted proxy uvicorn puts the forwarded client here."""
    client = scope.get("client")
    if not client:
        return None
    try:
        address = ipaddress.ip_address(str(client[0]).split("%")[0])
    except ValueError:
        return None
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    return None if address.is_loopback else str(client[0])


async def _authenticate(headers: Headers, sign_ins: SignIns) -> tuple[Principal | None, SignedIn | None]:
    authorization = headers.get("authorization", "")
    if authorization.lower().startswith("bearer ") and authorization[7:].strip().startswith(accounts.TOKEN_PREFIX):
        secret = authorization[7:].strip()
        return await anyio.to_thread.run_sync(sign_ins.accounts.verify_token, secret), None
    cookie = cookies.value(headers.get("cookie"), SESSION_COOKIE)
    if cookie is None:
        return None, None
    signed_in = await anyio.to_thread.run_sync(sign_ins.sessions.load, cookie)
    if signed_in is None:
        return None, None
    user = sign_ins.accounts.account(signed_in.name)
    if user is None or user.disabled or user.stamp != signed_in.stamp:
        return None, None  # the user was disabled, removed or given a new password: sign in again
    return Principal(user.name, user.role, via="login"), signed_in


async def _csrf_token(scope: Scope, receive: Receive, headers: Headers) -> tuple[str | None, Receive]:
    """The CSRF token from the header, else from a form's ``csrf_token`` field (the body is read once and replayed
    to the route)."""
    if (header := headers.get(CSRF_HEADER)) is not None:
        return header, receive
    content_type = headers.get("content-type", "")
    if not content_type.startswith(("application/x-www-form-urlencoded", "multipart/form-data")):
        return None, receive
    chunks: list[bytes] = []
    size, more = 0, True
    while more:
        message = await receive()
        if message["type"] != "http.request":
            return None, receive
        chunks.append(message.get("body", b""))
        size += len(chunks[-1])
        more = message.get("more_body", False)
        if size > (settings.max_batch_upload_bytes if route_path(scope) in BATCH_PATHS
                   else settings.max_upload_bytes) + 65536:
            return None, receive
    body = b"".join(chunks)
    replay = _body_once(body, receive)
    try:
        form = await Request(scope, _body_once(body, _disconnected)).form()
        token = form.get(CSRF_FIELD)
        await form.close()
    except Exception:  # a malformed form has no token; the route reports what is wrong with it
        return None, replay
    return (token if isinstance(token, str) else None), replay


def _body_once(body: bytes, then: Receive) -> Receive:
    """A receive that hands out the body already read as one message, then whatever ``then`` receives."""
    sent = False

    async def receive_body() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await then()

    return receive_body


async def _disconnected() -> Message:
    return {"type": "http.disconnect"}


async def _refuse_host(scope: Scope, receive: Receive, send: Send, reason: str) -> None:
    """400: problem+json for the API and websockets, plain text for anything else (no page of ours is rendered
    for a name that is not ours)."""
    exc = UnknownHostName(_("Refused: {reason}. A web page may have pointed its own name at this machine (DNS "
                            "rebinding), so DriveBench answers only to its own names.").format(reason=reason),
                          hint=_("Open DriveBench as http://127.0.0.1:PORT or by a name given to `drivebench serve "
                                 "--allowed-host NAME` (DRIVEBENCH_ALLOWED_HOSTS)."))
    if scope["type"] == "websocket":
        await send({"type": "websocket.close", "code": 4400, "reason": exc.detail[:120]})
        return
    body = problem_body(exc, scope.get("path", ""))
    response: Response
    if route_path(scope).startswith("/api/"):
        response = JSONResponse(body, status_code=400, media_type="application/problem+json")
    else:
        response = PlainTextResponse(f"{exc.detail}\n{exc.hint}\n", status_code=400)
    await response(scope, receive, send)


async def _refuse(scope: Scope, receive: Receive, send: Send, exc: DriveBenchError) -> None:
    unauthenticated = isinstance(exc, NotAuthenticated)
    if scope["type"] == "websocket":
        await send({"type": "websocket.close", "code": 4401 if unauthenticated else 4403,
                    "reason": exc.detail[:120]})
        return
    request = Request(scope, receive)
    path = route_path(scope)
    body = problem_body(exc, scope.get("path", ""))
    status = int(body["status"])  # type: ignore[call-overload]
    response: Response
    if unauthenticated and wants_page(request):
        target = path + (f"?{request.url.query}" if request.url.query else "")
        response = RedirectResponse(under_root(scope, f"/login?next={quote(target)}"), status_code=303)
    elif request.headers.get("HX-Request") == "true":
        response = HTMLResponse(error_fragment(body), status_code=status)
        if unauthenticated:
            response.headers["HX-Redirect"] = under_root(scope, "/login")
    elif wants_page(request):
        response = error_page(request, body)
    else:
        response = JSONResponse(body, status_code=status, media_type="application/problem+json")
    if unauthenticated and not wants_page(request):
        response.headers["WWW-Authenticate"] = 'Bearer realm="DriveBench"'
    await response(scope, receive, send)


# --- the app -----------------------------------------------------------------------------------------------------
_CONVERTOR = re.compile(r"\{(\w+):\w+\}")


def install(app: FastAPI) -> None:
    """Each operation's role in the OpenAPI document (``x-drivebench-role``); ``web/gate.py`` enforces them."""
    generate = app.openapi

    def openapi_with_roles() -> dict[str, Any]:
        schema = generate()
        for method, template, rule in access_policy.operations(app):
            operation = schema.get("paths", {}).get(_CONVERTOR.sub(r"{\1}", template), {}).get(method.lower())
            if operation is not None:
                public = (method, template) in access_policy.PUBLIC
                operation["x-drivebench-role"] = "public" if public else rule.role.label
        return schema

    app.openapi = openapi_with_roles  # type: ignore[method-assign]
