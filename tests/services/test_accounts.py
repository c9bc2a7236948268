"""Users, passwords (argon2, never stored), API tokens (hash only) and the sign-in rate limit, on a database of the
test's own."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import event, select

from drivebench.config import settings
from drivebench.errors import AccessDenied, Conflict, InvalidValue, NotAuthenticated
from drivebench.services.storage import database
from drivebench.services.storage.models import ApiTokenRow, SignedOutSessionRow, UserRow
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from tests.conftest import PRODUCT_HASHER


@pytest.fixture
def db(database_url: str, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """Accounts in a new SQLite file and again in a new PostgreSQL database."""
    monkeypatch.setattr(settings, "database_url", database_url)
    database.upgrade_to_head(database_url)
    yield database_url


def test_passwords_are_argon2_hashes_and_never_stored(db: str) -> None:
    accounts.create_user("anna", "correct horse battery", Role.ENGINEER)
    with database.transaction() as session:
        row = session.scalar(select(UserRow).where(UserRow.name == "anna"))
        assert row is not None
        assert row.password_hash.startswith("$argon2id$") and "correct horse" not in row.password_hash
    database.dispose()
    if db.startswith("sqlite:///"):
        assert b"correct horse" not in Path(db.removeprefix("sqlite:///")).read_bytes()
    assert accounts.verify_password("anna", "correct horse battery").role is Role.ENGINEER


def test_the_product_hashes_with_argon2id_at_64_mib_three_passes_and_four_lanes() -> None:
    """The suite hashes with argon2-cffi's cheapest parameters (tests/conftest.py ``cheap_password_hashes``); the
    product keeps argon2-cffi's default, RFC 9106's low-memory choice."""
    assert PRODUCT_HASHER.hash("correct horse battery").startswith("$argon2id$v=19$m=65536,t=3,p=4$")
    assert accounts._hasher is not PRODUCT_HASHER  # the cheap one, for this run only


def test_wrong_password_unknown_and_disabled_users_get_the_same_answer(db: str) -> None:
    accounts.create_user("root", "admin password", Role.ADMIN)
    accounts.create_user("anna", "anna password", Role.VIEWER)
    accounts.set_disabled("anna")
    answers = []
    for name, password in [("root", "wrong password"), ("nobody", "admin password"), ("anna", "anna password")]:
        with pytest.raises(NotAuthenticated) as refused:
            accounts.verify_password(name, password)
        answers.append(refused.value.detail)
    assert answers == ["Wrong user name or password."] * 3


def test_authentication_is_configured_by_an_enabled_admin_and_the_last_admin_stays(db: str) -> None:
    assert not accounts.authentication_configured()
    accounts.create_user("vera", "viewer password", Role.VIEWER)
    assert not accounts.authentication_configured()
    accounts.create_user("root", "admin password", Role.ADMIN)
    assert accounts.authentication_configured()
    with pytest.raises(Conflict, match="last enabled admin"):
        accounts.set_disabled("root")
    with pytest.raises(Conflict, match="last enabled admin"):
        accounts.set_role("root", Role.ENGINEER)
    accounts.create_user("second", "admin password", Role.ADMIN)
    accounts.set_disabled("root")
    assert accounts.authentication_configured()
    with pytest.raises(Conflict):
        accounts.create_user("vera", "another password", Role.VIEWER)


@pytest.mark.parametrize(("name", "password", "message"), [
    ("bad name!", "long enough", "not allowed"), ("", "long enough", "not allowed"), ("ok", "short", "too short"),
])
def test_bad_names_and_short_passwords_are_refused_in_words(db: str, name: str, password: str,
                                                            message: str) -> None:
    with pytest.raises(InvalidValue, match=message):
        accounts.create_user(name, password, Role.VIEWER)


def test_a_new_password_changes_the_stamp_that_sessions_carry(db: str) -> None:
    before = accounts.create_user("anna", "first password", Role.VIEWER)
    after = accounts.set_password("anna", "second password")
    assert before.stamp != after.stamp
    with pytest.raises(NotAuthenticated):
        accounts.verify_password("anna", "first password")


def test_tokens_are_shown_once_stored_as_hash_and_never_above_their_owner(db: str) -> None:
    accounts.create_user("root", "admin password", Role.ADMIN)
    accounts.create_user("eve", "engineer password", Role.ENGINEER)
    with pytest.raises(AccessDenied, match="cannot have the admin role"):
        accounts.issue_token("eve", "backup", Role.ADMIN)
    issued = accounts.issue_token("eve", "nightly read", Role.ENGINEER)
    assert issued.secret.startswith("dbt_") and len(issued.secret) > 40
    with database.transaction() as session:
        row = session.scalar(select(ApiTokenRow))
        assert row is not None and issued.secret not in (row.token_hash, row.hint) and row.hint == issued.secret[:10]
    principal = accounts.verify_token(issued.secret)
    assert (principal.name, principal.role, principal.via) == ("eve", Role.ENGINEER, "token")
    accounts.set_role("eve", Role.VIEWER)  # the lower of token and owner counts
    assert accounts.verify_token(issued.secret).role is Role.VIEWER
    assert accounts.list_tokens("eve")[0].last_used is not None
    accounts.revoke_token(issued.token.id)
    with pytest.raises(NotAuthenticated, match="unknown or revoked"):
        accounts.verify_token(issued.secret)
    with pytest.raises(NotAuthenticated):
        accounts.verify_token("dbt_" + "x" * 43)


def test_a_disabled_owner_s_tokens_stop_working(db: str) -> None:
    accounts.create_user("root", "admin password", Role.ADMIN)
    accounts.create_user("eve", "engineer password", Role.ENGINEER)
    issued = accounts.issue_token("eve", "script", Role.VIEWER)
    accounts.set_disabled("eve")
    with pytest.raises(NotAuthenticated):
        accounts.verify_token(issued.secret)
    accounts.set_disabled("eve", False)  # enabled again: she signs in, but the old tokens stay dead
    with pytest.raises(NotAuthenticated, match="unknown or revoked"):
        accounts.verify_token(issued.secret)
    assert accounts.list_tokens("eve")[0].revoked is not None
    fresh = accounts.issue_token("eve", "new script", Role.VIEWER)
    assert accounts.verify_token(fresh.secret).name == "eve"


def test_a_verified_token_is_not_looked_up_again_until_revoked(db: str) -> None:
    """Requests in a row with one token cost one database round trip, not one each; revoking it or disabling its
    owner counts at once."""
    accounts.create_user("root", "admin password", Role.ADMIN)
    accounts.create_user("eve", "engineer password", Role.ENGINEER)
    issued = accounts.issue_token("eve", "script", Role.ENGINEER)
    other = accounts.issue_token("eve", "second", Role.VIEWER)
    statements: list[str] = []

    def count(_conn: object, _cursor: object, statement: str, *_args: object) -> None:
        statements.append(statement)

    known = accounts.Accounts()  # a server's memory of the accounts (web/state.AppState.accounts)
    engine = database.engine(db)
    event.listen(engine, "before_cursor_execute", count)
    try:
        for _ in range(5):
            assert known.verify_token(issued.secret).role is Role.ENGINEER
        assert len([s for s in statements if "from api_token" in s.lower()]) == 1
        known.revoke_token(issued.token.id)
        with pytest.raises(NotAuthenticated, match="unknown or revoked"):
            known.verify_token(issued.secret)
        assert known.verify_token(other.secret).role is Role.VIEWER
        known.set_disabled("eve")
        with pytest.raises(NotAuthenticated):
            known.verify_token(other.secret)
    finally:
        event.remove(engine, "before_cursor_execute", count)


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_five_failures_lock_the_name_with_a_growing_lock_said_in_words(db: str) -> None:
    clock = FakeClock()
    limiter = accounts.LoginLimiter(max_failures=5, first_lock_s=30, max_lock_s=600, clock=clock)
    for _ in range(4):
        limiter.failed("user:anna")
        limiter.check("user:anna", "for anna")  # not locked yet
    limiter.failed("user:anna")
    with pytest.raises(accounts.LoginLocked) as locked:
        limiter.check("user:anna", "for anna")
    assert locked.value.detail == "Too many failed sign-ins for anna: try again in 30 seconds."
    assert locked.value.retry_after_s == 30
    limiter.check("user:bert", "for bert")  # others are not affected
    clock.now += 31
    limiter.check("user:anna", "for anna")
    limiter.failed("user:anna")  # the sixth failure: twice as long
    with pytest.raises(accounts.LoginLocked, match="1 minute"):
        limiter.check("user:anna", "for anna")
    clock.now += 61
    limiter.succeeded("user:anna")
    limiter.failed("user:anna")
    limiter.check("user:anna", "for anna")  # a success started the count again


def test_a_lock_is_kept_in_the_database_for_every_server_and_a_restart(db: str) -> None:
    clock = FakeClock()
    here = accounts.LoginLimiter(max_failures=3, first_lock_s=30, clock=clock)
    for _ in range(3):
        here.failed("user:anna")
    elsewhere = accounts.LoginLimiter(max_failures=3, first_lock_s=30, clock=clock)  # another server, a restart
    with pytest.raises(accounts.LoginLocked, match="try again in 30 seconds"):
        elsewhere.check("user:anna", "for anna")
    elsewhere.succeeded("user:anna")
    here.check("user:anna", "for anna")


def test_a_signed_out_session_is_refused_until_it_would_have_expired(db: str) -> None:
    assert not accounts.session_signed_out("sid-1")
    accounts.sign_out_session("sid-1", 3600)
    accounts.sign_out_session("sid-1", 3600)  # twice (two tabs) is no error
    assert accounts.session_signed_out("sid-1")
    assert not accounts.session_signed_out("sid-2")
    accounts.sign_out_session("sid-2", -1)  # already expired: the next sign-out clears it away
    accounts.sign_out_session("sid-3", 3600)
    with database.transaction() as session:
        assert session.scalars(select(SignedOutSessionRow.sid).order_by(SignedOutSessionRow.sid)).all() == [
            "sid-1", "sid-3"]


def test_in_words() -> None:
    assert [accounts.in_words(s) for s in (0.2, 1, 30, 60, 95, 600)] == [
        "1 second", "1 second", "30 seconds", "1 minute", "1 minute 35 seconds", "10 minutes"]


def test_sign_in_counts_failures_per_name_and_per_address(db: str) -> None:
    accounts.create_user("root", "admin password", Role.ADMIN)
    clock = FakeClock()
    sign_in = accounts.SignIn(per_user=accounts.LoginLimiter(max_failures=3, clock=clock),
                              per_address=accounts.LoginLimiter(max_failures=5, clock=clock))
    for _ in range(3):
        with pytest.raises(NotAuthenticated):
            sign_in("root", "guess", "10.0.0.9")
    with pytest.raises(accounts.LoginLocked, match="for root: try again in 30 seconds"):
        sign_in("root", "admin password", "10.0.0.7")  # even the right password waits
    for name in ("a1", "a2"):
        with pytest.raises(NotAuthenticated):
            sign_in(name, "guess", "10.0.0.9")
    with pytest.raises(accounts.LoginLocked, match=r"from 10\.0\.0\.9"):
        sign_in("b1", "guess", "10.0.0.9")
    clock.now += 31
    assert sign_in("root", "admin password", "10.0.0.7").name == "root"
