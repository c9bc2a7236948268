"""Share links in the database: any server of the database (here: another ShareLinks, as a second server or a
restart has) opens, lists and revokes them; only a digest of the token is stored."""

from __future__ import annotations

import pytest
from sqlalchemy import select

from drivebench.config import settings
from drivebench.errors import NotAuthenticated, NotFound
from drivebench.services.storage import database
from drivebench.services.storage.models import ShareLinkRow
from drivebench.services.users.sharing import ShareLinks


@pytest.fixture
def db(database_url: str, monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setattr(settings, "database_url", database_url)
    database.upgrade_to_head(database_url)
    return database_url


def test_a_link_made_by_one_server_opens_on_another_and_its_revocation_holds_there(db: str) -> None:
    issued = ShareLinks().create(3600, "  line 3 drive  ")
    other = ShareLinks()
    assert other.check(issued.token) == issued.link
    assert [link.label for link in other.active()] == ["line 3 drive"]
    with database.transaction() as session:
        stored = session.scalars(select(ShareLinkRow)).one()
        assert issued.token not in (stored.token_hash, stored.hint, stored.id) and stored.hint == issued.token[:8]
    ShareLinks().revoke(issued.link.id)
    with pytest.raises(NotAuthenticated, match="not valid"):
        other.check(issued.token)
    with pytest.raises(NotFound):
        other.revoke(issued.link.id)


def test_revoked_by_token_and_expired_links_are_refused(db: str) -> None:
    links = ShareLinks()
    by_token = links.create(3600)
    links.revoke(by_token.token)
    with pytest.raises(NotAuthenticated):
        links.check(by_token.token)
    short = links.create(60)
    with database.transaction() as session:
        session.get(ShareLinkRow, short.link.id).expires = 40_000_000.0  # type: ignore[union-attr]
    with pytest.raises(NotAuthenticated, match="expired at 1971"):
        links.check(short.token)
    assert links.active() == []
