"""Users, passwords and API tokens in the database, and the sign-in rate limit.

Passwords are hashed with argon2 (argon2-cffi's ``PasswordHasher``); the database holds the hash only. An API
token (``dbt_`` + 43 random characters) is shown once when issued; the database holds its SHA-256 (the token is
random, so a fast hash is enough) and its first characters as a hint. Authentication is *configured* as soon as one
enabled admin exists: from then on the web server asks everyone to sign in.

The functions read and change the database as they are called (the CLI uses them). A web app asks its
:class:`Accounts` (``web/state.AppState.accounts``): the users and verified tokens it read lately, forgotten at once
when a change goes through it; no account state lives in this module.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import re
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import cached_property
from typing import TYPE_CHECKING, TypeVar

from sqlalchemy import delete, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from drivebench.config import settings
from drivebench.errors import AccessDenied, Conflict, InvalidValue, NotAuthenticated, NotFound
from drivebench.i18n import N_, _, ngettext
from drivebench.services.storage.database import transaction
from drivebench.services.storage.models import (
    ApiTokenRow,
    SignedOutSessionRow,
    SignInFailureRow,
    UserRow,
    new_session_stamp,
    utcnow,
)
from drivebench.services.users.principals import Principal, Role

if TYPE_CHECKING:
    from argon2 import PasswordHasher

log = logging.getLogger(__name__)

TOKEN_PREFIX = "dbt_"
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._@-]{0,59}")
MIN_PASSWORD_LENGTH = 8
MAX_PASSWORD_LENGTH = 1024
MAX_LIMIT_KEY = 300  # a sign-in limit key (``user:`` + the name as typed) is cut to the column
DIRECTORY_TTL_S = 2.0  # a user added by the CLI while the server runs counts after at most this long

_T = TypeVar("_T")


class _ProductHasher:
    """argon2-cffi's ``PasswordHasher`` with its default (the product's) parameters, made at the first hash or check:
    importing argon2 loads its C bindings, a few hundredths of a second of every server start before it could
    answer ``/api/health`` (issue 33)."""

    @cached_property
    def _argon2(self) -> PasswordHasher:
        from argon2 import PasswordHasher

        return PasswordHasher()

    def hash(self, password: str) -> str:
        return self._argon2.hash(password)

    def verify(self, password_hash: str, password: str) -> bool:
        return self._argon2.verify(password_hash, password)

    def check_needs_rehash(self, password_hash: str) -> bool:
        return self._argon2.check_needs_rehash(password_hash)


_hasher = _ProductHasher()
_dummy_hash: str | None = None


@dataclass(frozen=True)
class User:
    id: int
    name: str
    role: Role
    created: datetime
    disabled: bool
    stamp: str
    """The session stamp: a signed-in session carries it, and it changes on disable, enable, new password and new
    role, so those end the old sessions (on every server of the database: it is stored there)."""


@dataclass(frozen=True)
class ApiToken:
    id: int
    name: str
    owner: str
    role: Role
    hint: str
    created: datetime
    last_used: datetime | None
    revoked: datetime | None


@dataclass(frozen=True)
class IssuedToken:
    token: ApiToken
    secret: str
    """The token itself: shown once, never stored."""


class LoginLocked(NotAuthenticated):
    title = N_("Too many failed sign-ins")

    def __init__(self, detail: str, *, retry_after_s: int) -> None:
        super().__init__(detail, hint=N_("Wait, then sign in again; an admin can reset a forgotten password."))
        self.retry_after_s = retry_after_s

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "retry_after_s": self.retry_after_s}


# --- checks ----------------------------------------------------------------------------------------------------
def _check_name(name: str) -> str:
    name = name.strip()
    if not NAME_PATTERN.fullmatch(name):
        raise InvalidValue(_("User name {name} is not allowed: use 1 to 60 letters, digits, '.', '_', '@' or '-', "
                             "starting with a letter or digit.").format(name=repr(name)))
    return name


def _check_password(password: str) -> str:
    if len(password) < MIN_PASSWORD_LENGTH:
        raise InvalidValue(_("The password is too short: use at least {count} characters.").format(
            count=MIN_PASSWORD_LENGTH))
    if len(password) > MAX_PASSWORD_LENGTH:
        raise InvalidValue(_("The password is too long: use at most {count} characters.").format(
            count=MAX_PASSWORD_LENGTH))
    return password


def _user(row: UserRow) -> User:
    return User(row.id, row.name, Role.parse(row.role), row.created, row.disabled, row.session_stamp)


def _token(row: ApiTokenRow, owner: str) -> ApiToken:
    return ApiToken(row.id, row.name, owner, Role.parse(row.role), row.hint, row.created, row.last_used,
                    row.revoked)


def _token_hash(secret: str) -> str:
    return hashlib.sha256(secret.encode()).hexdigest()


# --- the directory: users by name, cached briefly (every request asks whether login is required) --------------
class Directory:
    """The users by name as read at most ``DIRECTORY_TTL_S`` ago; a change read from the database (made elsewhere:
    another server, the CLI) forgets ``tokens``: they act with their owner's state as now read."""

    def __init__(self, tokens: VerifiedTokens) -> None:
        self._lock = threading.Lock()
        self._users: dict[str, User] = {}
        self._loaded_at = -DIRECTORY_TTL_S
        self._url: str | None = None
        self._tokens = tokens

    def users(self) -> dict[str, User]:
        with self._lock:
            fresh = time.monotonic() - self._loaded_at < DIRECTORY_TTL_S and self._url == settings.database_url
            if fresh:
                return self._users
        users = _read_users()
        with self._lock:
            changed = users != self._users
            self._users, self._loaded_at, self._url = users, time.monotonic(), settings.database_url
        if changed:
            self._tokens.forget()
        return users

    def forget(self) -> None:
        with self._lock:
            self._loaded_at = -DIRECTORY_TTL_S
        self._tokens.forget()  # a token acts with its owner's current role and state


class VerifiedTokens:
    """API tokens verified in the last ``DIRECTORY_TTL_S``, by hash: a script's requests in a row cost no database
    round trip each. Revoking a token or changing its owner forgets them all at once (through the same
    :class:`Accounts`; a change made elsewhere counts after at most ``DIRECTORY_TTL_S``, as for the directory)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._known: dict[str, tuple[float, Principal]] = {}
        self.generation = 0
        """Counts forgets: a verification that began before one is not kept (it may have read the old state)."""

    def get(self, token_hash: str) -> Principal | None:
        with self._lock:
            found = self._known.get(token_hash)
        return found[1] if found is not None and time.monotonic() - found[0] < DIRECTORY_TTL_S else None

    def put(self, token_hash: str, principal: Principal, generation: int) -> None:
        now = time.monotonic()
        with self._lock:
            if generation != self.generation:
                return
            self._known = {key: kept for key, kept in self._known.items() if now - kept[0] < DIRECTORY_TTL_S}
            self._known[token_hash] = (now, principal)

    def forget(self) -> None:
        with self._lock:
            self._known.clear()
            self.generation += 1


def _read_users() -> dict[str, User]:
    with transaction() as db:
        return {row.name: _user(row) for row in db.scalars(select(UserRow))}


def _configured(users: dict[str, User]) -> bool:
    return any(user.role is Role.ADMIN and not user.disabled for user in users.values())


def authentication_configured() -> bool:
    """True as soon as one enabled admin exists: then everyone signs in (read now; a server asks its
    :meth:`Accounts.authentication_configured`, read at most ``DIRECTORY_TTL_S`` ago)."""
    return _configured(_read_users())


# --- users -----------------------------------------------------------------------------------------------------
def create_user(name: str, password: str, role: Role) -> User:
    name = _check_name(name)
    password_hash = _hasher.hash(_check_password(password))
    with transaction() as db:
        if db.scalar(select(UserRow).where(UserRow.name == name)) is not None:
            raise Conflict(_("A user called {name} exists already.").format(name=name))
        created = _add_user(db, name, password_hash, role)
    return created


def _add_user(db: Session, name: str, password_hash: str, role: Role) -> User:
    row = UserRow(name=name, role=role.label, password_hash=password_hash, created=utcnow(), disabled=False)
    db.add(row)
    db.flush()
    return _user(row)


def create_first_admin(name: str, password: str) -> User | None:
    """The admin of a new installation (a container's first start): made only while no user exists at all, so a
    restart, with the same settings or others, changes nothing (None)."""
    name = _check_name(name)
    password_hash = _hasher.hash(_check_password(password))
    try:
        with transaction() as db:
            if db.scalar(select(UserRow.id).limit(1)) is not None:
                return None
            created = _add_user(db, name, password_hash, Role.ADMIN)
    except IntegrityError:  # another server of the database made it at the same moment
        return None
    return created


def list_users() -> list[User]:
    with transaction() as db:
        return [_user(row) for row in db.scalars(select(UserRow).order_by(UserRow.name))]


def get_user(name: str) -> User:
    with transaction() as db:
        return _user(_user_row(db, name))


def _user_row(db: Session, name: str) -> UserRow:
    row = db.scalar(select(UserRow).where(UserRow.name == name))
    if row is None:
        raise NotFound(_("There is no user called {name}.").format(name=name))
    return row


def _lock_admins(db: Session) -> None:
    """Hold the enabled admins' rows until the transaction ends, so two changes that each leave one admin (two
    admins disabling each other at once, on one server or two) run one after the other and the second sees the
    first. A write that changes nothing takes the lock on both databases: PostgreSQL locks the rows it matches (a
    waiting transaction then re-reads them), SQLite takes its write lock on the file."""
    db.execute(update(UserRow).where(UserRow.role == Role.ADMIN.label, UserRow.disabled.is_(False))
               .values(disabled=False))


def _keep_an_admin(db: Session, row: UserRow, *, role: Role, disabled: bool) -> None:
    """Refuse to leave no enabled admin: that would switch the sign-in off and open every screen to everyone."""
    if row.role != Role.ADMIN.label or row.disabled or (role is Role.ADMIN and not disabled):
        return
    admins = db.scalars(select(UserRow).where(UserRow.role == Role.ADMIN.label, UserRow.disabled.is_(False)))
    if len(list(admins)) <= 1:
        raise Conflict(_("{name} is the last enabled admin: without one, signing in would be switched off and "
                         "every screen open to anyone who reaches the server.").format(name=row.name),
                       hint=N_("Add another admin first."))


def set_disabled(name: str, disabled: bool = True) -> User:
    with transaction() as db:
        _lock_admins(db)
        row = _user_row(db, name)
        _keep_an_admin(db, row, role=Role.parse(row.role), disabled=disabled)
        if row.disabled != disabled:
            row.session_stamp = new_session_stamp()  # re-enabling does not bring the old sessions back
        if disabled:
            _revoke_tokens_of(db, row.id)  # nor the old API tokens
        row.disabled = disabled
        changed = _user(row)
    return changed


def set_role(name: str, role: Role) -> User:
    with transaction() as db:
        _lock_admins(db)
        row = _user_row(db, name)
        _keep_an_admin(db, row, role=role, disabled=row.disabled)
        if row.role != role.label:
            row.session_stamp = new_session_stamp()
        row.role = role.label
        changed = _user(row)
    return changed


def set_password(name: str, password: str, *, end_tokens: bool = False) -> User:
    """A new password ends the user's sessions; ``end_tokens`` (an admin's reset) revokes their API tokens too:
    whoever needed the reset may have had them taken."""
    password_hash = _hasher.hash(_check_password(password))
    with transaction() as db:
        row = _user_row(db, name)
        row.password_hash = password_hash
        row.session_stamp = new_session_stamp()
        if end_tokens:
            _revoke_tokens_of(db, row.id)
        changed = _user(row)
    return changed


def verify_password(name: str, password: str) -> Principal:
    """The principal of a correct name and password; ``NotAuthenticated`` (in the same words) otherwise."""
    from argon2.exceptions import InvalidHashError, VerificationError

    global _dummy_hash
    wrong = NotAuthenticated(_("Wrong user name or password."))
    with transaction() as db:
        row = db.scalar(select(UserRow).where(UserRow.name == name.strip()))
        if row is None or row.disabled:
            _dummy_hash = _dummy_hash or _hasher.hash(secrets.token_hex(8))
            with contextlib.suppress(VerificationError):  # as slow as a real check: the time tells no names
                _hasher.verify(_dummy_hash, password)
            raise wrong
        try:
            _hasher.verify(row.password_hash, password)
        except (VerificationError, InvalidHashError):
            raise wrong from None
        if _hasher.check_needs_rehash(row.password_hash):
            row.password_hash = _hasher.hash(password)
        return Principal(row.name, Role.parse(row.role), via="login")


# --- API tokens ------------------------------------------------------------------------------------------------
def issue_token(owner: str, name: str, role: Role, *, parent: int | None = None) -> IssuedToken:
    """A new token of ``owner``; ``parent``: the id of the token whose request makes it (it ends with that one)."""
    name = name.strip()
    if not 1 <= len(name) <= 120:
        raise InvalidValue(_("Give the token a name of 1 to 120 characters (what the script does)."))
    secret = TOKEN_PREFIX + secrets.token_urlsafe(32)
    with transaction() as db:
        user = _user_row(db, owner)
        if role > Role.parse(user.role):
            raise AccessDenied(_("A token of {owner} cannot have the {role} role: {owner} is {owner_role}.").format(
                owner=owner, role=role.label, owner_role=Role.parse(user.role).label))
        row = ApiTokenRow(name=name, owner_id=user.id, role=role.label, token_hash=_token_hash(secret),
                          hint=secret[:10], created=utcnow(), parent_id=parent)
        db.add(row)
        db.flush()
        return IssuedToken(_token(row, user.name), secret)


def list_tokens(owner: str | None = None) -> list[ApiToken]:
    with transaction() as db:
        query = select(ApiTokenRow, UserRow.name).join(UserRow, ApiTokenRow.owner_id == UserRow.id)
        if owner is not None:
            query = query.where(UserRow.name == owner)
        return [_token(row, owner_name) for row, owner_name in db.execute(query.order_by(ApiTokenRow.id))]


def revoke_token(token_id: int, *, owner: str | None = None) -> ApiToken:
    """Revoke a token (of ``owner`` only, when given: a user may revoke their own tokens)."""
    with transaction() as db:
        found = db.execute(select(ApiTokenRow, UserRow.name).join(UserRow, ApiTokenRow.owner_id == UserRow.id)
                           .where(ApiTokenRow.id == token_id)).first()
        if found is None or (owner is not None and found[1] != owner):
            raise NotFound(_("There is no API token {id} of {owner}.").format(id=token_id, owner=owner) if owner
                           else _("There is no API token {id}.").format(id=token_id))
        row, owner_name = found
        row.revoked = row.revoked or utcnow()
        _revoke_descendants(db, [row.id])
        return _token(row, owner_name)


def _revoke_tokens_of(db: Session, user_id: int) -> None:
    ids = list(db.scalars(select(ApiTokenRow.id).where(ApiTokenRow.owner_id == user_id)))
    db.execute(update(ApiTokenRow).where(ApiTokenRow.owner_id == user_id, ApiTokenRow.revoked.is_(None))
               .values(revoked=utcnow()))
    _revoke_descendants(db, ids)


def _revoke_descendants(db: Session, ids: list[int]) -> None:
    """Revoke the tokens made with the tokens ``ids``, and those made with them, and so on (the list shows what
    ``verify_token`` refuses anyway)."""
    while ids:
        ids = list(db.scalars(select(ApiTokenRow.id).where(ApiTokenRow.parent_id.in_(ids))))
        if ids:
            db.execute(update(ApiTokenRow).where(ApiTokenRow.id.in_(ids), ApiTokenRow.revoked.is_(None))
                       .values(revoked=utcnow()))


def _ancestors_valid(db: Session, parent_id: int | None) -> bool:
    """Whether every token up the chain that made a token is unrevoked and its owner enabled (a parent revoked
    while it was minting a child is caught here, not only by ``_revoke_descendants``)."""
    seen: set[int] = set()
    while parent_id is not None and parent_id not in seen:
        seen.add(parent_id)
        found = db.execute(select(ApiTokenRow, UserRow).join(UserRow, ApiTokenRow.owner_id == UserRow.id)
                           .where(ApiTokenRow.id == parent_id)).first()
        if found is None or found[0].revoked is not None or found[1].disabled:
            return False
        parent_id = found[0].parent_id
    return parent_id is None


def verify_token(secret: str) -> Principal:
    """The principal a token acts as: the lower of the token's and its owner's current role (read now; a server
    asks its :meth:`Accounts.verify_token`, which remembers it ``DIRECTORY_TTL_S``)."""
    return _verified(_token_hash(_check_token_form(secret)))


def _refused() -> NotAuthenticated:
    return NotAuthenticated(_("The API token is unknown or revoked."),
                            hint=N_("Create a new token on the Users page or with `drivebench tokens create`."))


def _check_token_form(secret: str) -> str:
    if not secret.startswith(TOKEN_PREFIX):
        raise _refused()
    return secret


def _verified(token_hash: str) -> Principal:
    with transaction() as db:
        found = db.execute(select(ApiTokenRow, UserRow).join(UserRow, ApiTokenRow.owner_id == UserRow.id)
                           .where(ApiTokenRow.token_hash == token_hash)).first()
        if found is None or found[0].revoked is not None or found[1].disabled:
            raise _refused()
        row, user = found
        if not _ancestors_valid(db, row.parent_id):
            raise _refused()
        now = utcnow()
        if row.last_used is None or (now - _aware(row.last_used)).total_seconds() > 60:  # not a write per request
            row.last_used = now
        role = min(Role.parse(row.role), Role.parse(user.role))
        return Principal(user.name, role, via="token", token_id=row.id)


def _aware(moment: datetime) -> datetime:
    """SQLite returns naive datetimes for timezone-aware columns; they were stored in UTC."""
    return moment if moment.tzinfo else moment.replace(tzinfo=UTC)


# --- signed-out cookie sessions ------------------------------------------------------------------------------
def sign_out_session(sid: str, max_age_s: float) -> None:
    """Refuse the cookie session ``sid`` from now on, on every server of the database (until it would expire)."""
    now = time.time()
    with transaction() as db:
        db.execute(delete(SignedOutSessionRow).where(SignedOutSessionRow.until < now))
        if db.get(SignedOutSessionRow, sid) is None:
            db.add(SignedOutSessionRow(sid=sid, until=now + max_age_s))


def session_signed_out(sid: str) -> bool:
    with transaction() as db:
        return db.get(SignedOutSessionRow, sid) is not None


# --- the sign-in rate limit ------------------------------------------------------------------------------------
def in_words(seconds: float) -> str:
    """``95`` -> ``1 minute 35 seconds``."""
    whole = max(1, int(seconds + 0.999))
    minutes, rest = divmod(whole, 60)
    parts = []
    if minutes:
        parts.append(ngettext("{count} minute", "{count} minutes", minutes).format(count=minutes))
    if rest or not minutes:
        parts.append(ngettext("{count} second", "{count} seconds", rest).format(count=rest))
    return " ".join(parts)


class LoginLimiter:
    """Failed sign-ins per key (a user name, a client address), counted in the database so a lock holds on every
    server and across a restart: after ``max_failures`` the key is locked for ``first_lock_s``, and each further
    failure doubles the lock, up to ``max_lock_s``. A success clears the key; so does ``max_lock_s`` without a
    failure once the lock is over. ``clock`` gives seconds since the epoch (the servers share the rows)."""

    def __init__(self, max_failures: int = 5, first_lock_s: float = 30.0, max_lock_s: float = 900.0,
                 clock: Callable[[], float] = time.time, url: str | None = None) -> None:
        self.max_failures = max_failures
        self.first_lock_s = first_lock_s
        self.max_lock_s = max_lock_s
        self._clock = clock
        self.url = url

    def check(self, key: str, what: str) -> None:
        """Raise ``LoginLocked`` while ``key`` is locked (``what`` names it in the message)."""
        with transaction(self.url) as db:
            entry = db.get(SignInFailureRow, key[:MAX_LIMIT_KEY])
            left = entry.locked_until - self._clock() if entry else 0.0
        if left > 0:
            raise LoginLocked(_("Too many failed sign-ins {what}: try again in {wait}.").format(
                what=what, wait=in_words(left)), retry_after_s=max(1, int(left + 0.999)))

    def failed(self, key: str) -> None:
        now, key = self._clock(), key[:MAX_LIMIT_KEY]
        for attempt in (1, 2, 3):
            try:
                with transaction(self.url) as db:
                    db.execute(delete(SignInFailureRow).where(SignInFailureRow.locked_until < now,
                                                              SignInFailureRow.last < now - self.max_lock_s))
                    entry = db.scalar(select(SignInFailureRow).where(SignInFailureRow.key == key).with_for_update())
                    if entry is None:
                        entry = SignInFailureRow(key=key, count=0, locked_until=0.0, last=now)
                        db.add(entry)
                    entry.count += 1
                    entry.last = now
                    if entry.count >= self.max_failures:
                        lock = self.first_lock_s * 2 ** (entry.count - self.max_failures)
                        entry.locked_until = now + min(lock, self.max_lock_s)
                return
            except IntegrityError:  # another server counted the key's first failure at the same moment
                if attempt == 3:
                    raise

    def succeeded(self, key: str) -> None:
        with transaction(self.url) as db:
            db.execute(delete(SignInFailureRow).where(SignInFailureRow.key == key[:MAX_LIMIT_KEY]))


class SignIn:
    """Sign-in with a rate limit per user name (5 failures) and per client address (20: several people may share
    one address)."""

    def __init__(self, *, per_user: LoginLimiter | None = None, per_address: LoginLimiter | None = None) -> None:
        self.per_user = per_user or LoginLimiter(max_failures=5)
        self.per_address = per_address or LoginLimiter(max_failures=20)

    def __call__(self, name: str, password: str, address: str) -> Principal:
        user_key, address_key = f"user:{name.strip().lower()}", f"address:{address}"
        shown_name = name.strip()[:64]  # never the password: only who tried, from where, and what happened
        try:
            self.per_user.check(user_key, _("for {name}").format(name=shown_name))
            self.per_address.check(address_key, _("from {address}").format(address=address))
        except LoginLocked:
            log.warning("sign-in refused for user %r from %s: too many failed attempts", shown_name, address)
            raise
        try:
            principal = verify_password(name, password)
        except NotAuthenticated:
            self.per_user.failed(user_key)
            self.per_address.failed(address_key)
            log.warning("sign-in failed for user %r from %s: wrong name or password", shown_name, address)
            raise
        self.per_user.succeeded(user_key)
        self.per_address.succeeded(address_key)
        return principal



class Accounts:
    """One server's memory of the accounts: the directory and the verified API tokens (each kept at most
    ``DIRECTORY_TTL_S``) and the sign-in with its rate limits (counted in the database). A web app holds one
    (``web/state.AppState.accounts``); a change made through it counts for that app at once, one made elsewhere (the
    CLI, another server, another app in the process) after at most ``DIRECTORY_TTL_S``."""

    def __init__(self, sign_in: SignIn | None = None) -> None:
        self.tokens = VerifiedTokens()
        self.directory = Directory(self.tokens)
        self.sign_in = sign_in or SignIn()

    def forget(self) -> None:
        """Read the users and tokens from the database on the next question."""
        self.directory.forget()

    def authentication_configured(self) -> bool:
        return _configured(self.directory.users())

    def account(self, name: str) -> User | None:
        """The user called ``name`` as of at most ``DIRECTORY_TTL_S`` ago (None: no such user)."""
        return self.directory.users().get(name)

    def verify_token(self, secret: str) -> Principal:
        """As :func:`verify_token`, remembered ``DIRECTORY_TTL_S`` (a script's requests in a row)."""
        token_hash = _token_hash(_check_token_form(secret))
        if (known := self.tokens.get(token_hash)) is not None:
            return known
        generation = self.tokens.generation
        principal = _verified(token_hash)
        self.tokens.put(token_hash, principal, generation)
        return principal

    # --- changes: as the functions of the same name, then forgotten here at once ---------------------------
    def create_user(self, name: str, password: str, role: Role) -> User:
        return self._changed(create_user(name, password, role))

    def set_disabled(self, name: str, disabled: bool = True) -> User:
        return self._changed(set_disabled(name, disabled))

    def set_role(self, name: str, role: Role) -> User:
        return self._changed(set_role(name, role))

    def set_password(self, name: str, password: str, *, end_tokens: bool = False) -> User:
        return self._changed(set_password(name, password, end_tokens=end_tokens))

    def revoke_token(self, token_id: int, *, owner: str | None = None) -> ApiToken:
        return self._changed(revoke_token(token_id, owner=owner))

    def _changed(self, result: _T) -> _T:
        self.forget()
        return result
