"""Database: the package's Alembic migrations on an empty SQLite file and PostgreSQL database, planned networks
saved and loaded, transactions rolled back on error, JSON export/import, and the comparison of a plan with scanned
nodes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from alembic.script import ScriptDirectory
from sqlalchemy import inspect, select

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import InvalidValue, NotFound
from drivebench.services.bus.sessions import SessionNode
from drivebench.services.planning.planned_networks import PlannedNetworkStore, compare_live
from drivebench.services.planning.planner import CableInput, NetworkPlan, PlannedNode
from drivebench.services.storage import database
from drivebench.services.storage.models import PlannedNetworkRow
from tests.conftest import shipped_switch_devices


@pytest.fixture
def db_url(database_url: str) -> str:
    """Each test runs on a new SQLite file and again on a new PostgreSQL database."""
    return database_url


@pytest.fixture
def store(db_url: str) -> PlannedNetworkStore:
    database.upgrade_to_head(db_url)
    return PlannedNetworkStore(db_url)


def plan(name: str = "Line 1") -> NetworkPlan:
    return NetworkPlan(
        name=name,
        nodes=[
            PlannedNode(name="Conveyor", device="lenze-8400-motec", node_id=5, baud_kbit=500, channels=["pdo1"]),
            PlannedNode(name="Fan", device="lenze-emf2178ib", node_id=12, baud_kbit=500, pdo_ids="canopen"),
        ],
        cable=CableInput(length_m=80),
    )


def test_migrations_create_the_schema_on_an_empty_database(db_url: str, tmp_path: Path) -> None:
    assert not (tmp_path / "db").exists()  # a SQLite file's folder is made on the first start-up
    database.upgrade_to_head(db_url)
    head = ScriptDirectory.from_config(database.alembic_config(db_url)).get_current_head()
    assert head is not None
    assert database.current_revision(db_url) == head
    columns = {c["name"] for c in inspect(database.engine(db_url)).get_columns("planned_network")}
    assert columns == {"id", "name", "created", "updated", "body"}
    database.upgrade_to_head(db_url)  # a second start-up finds the schema current and changes nothing
    assert database.current_revision(db_url) == head


def test_a_start_on_a_current_schema_runs_no_alembic_upgrade(db_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A start-up finds the schema at head and leaves Alembic's environment and scripts alone (issues 29 and 33: it
    cost every app start ~0.1 s); a database behind head is still upgraded."""
    from alembic import command

    upgrades: list[str] = []
    real_upgrade = command.upgrade

    def counted(config: object, revision: str, **kwargs: object) -> None:
        upgrades.append(revision)
        real_upgrade(config, revision, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(command, "upgrade", counted)
    database.upgrade_to_head(db_url)
    assert upgrades == ["head"]
    database.upgrade_to_head(db_url)
    assert upgrades == ["head"]
    command.downgrade(database.alembic_config(db_url), "-1")
    database.upgrade_to_head(db_url)
    assert upgrades == ["head", "head"]
    assert database.current_revision(db_url) == database.head_revision()


def test_the_start_reads_the_migrations_as_alembic_does(db_url: str) -> None:
    """The revisions and heads a start compares the database with (read from the files, without Alembic) are
    Alembic's, and so is the database's current revision at every step up from the first migration."""
    from alembic import command

    scripts = ScriptDirectory.from_config(database.alembic_config(db_url))
    carried = database.carried_revisions()
    assert carried.known == {script.revision for script in scripts.walk_revisions()}
    assert carried.heads == set(scripts.get_heads()) and len(carried.heads) == 1
    database.engine(db_url)  # makes a SQLite file's folder, as a server's start-up does
    with database.engine(db_url).connect() as connection:
        assert database.current_heads(connection) == frozenset()
    for script in reversed(list(scripts.walk_revisions())):
        command.upgrade(database.alembic_config(db_url), script.revision)
        with database.engine(db_url).connect() as connection:
            assert database.current_heads(connection) == {database.current_revision(db_url)} == {script.revision}


def test_migrations_go_down_and_up_again(db_url: str) -> None:
    from alembic import command

    database.upgrade_to_head(db_url)
    command.downgrade(database.alembic_config(db_url), "base")
    assert "planned_network" not in inspect(database.engine(db_url)).get_table_names()
    database.upgrade_to_head(db_url)
    assert "planned_network" in inspect(database.engine(db_url)).get_table_names()


def test_save_list_load_update_delete(store: PlannedNetworkStore) -> None:
    first = store.save(plan("Line 1"))
    second = store.save(plan("Hall A"))
    assert first.id != second.id
    assert [(s.name, s.node_count) for s in store.list()] == [("Hall A", 2), ("Line 1", 2)]
    loaded = store.get(first.id)
    assert loaded.plan == plan("Line 1")
    assert loaded.created.tzinfo is not None

    changed = plan("Line 1 (rebuilt)")
    changed.nodes.append(PlannedNode(device="siemens-mm4", node_id=3, baud_kbit=500))
    updated = store.update(first.id, changed)
    assert (updated.name, updated.created, len(updated.plan.nodes)) == ("Line 1 (rebuilt)", loaded.created, 3)
    assert updated.updated >= loaded.updated
    assert store.get(first.id).plan == changed

    store.delete(first.id)
    with pytest.raises(NotFound):
        store.get(first.id)
    with pytest.raises(NotFound):
        store.delete(first.id)
    assert [s.id for s in store.list()] == [second.id]


def test_a_failing_transaction_is_rolled_back(store: PlannedNetworkStore, db_url: str) -> None:
    kept = store.save(plan("kept"))
    with pytest.raises(RuntimeError), database.transaction(db_url) as db:
        db.add(PlannedNetworkRow(name="half-done", body={"nodes": []}))
        db.get(PlannedNetworkRow, kept.id).name = "renamed"  # type: ignore[union-attr]
        db.flush()  # the rows are in the database's transaction ...
        raise RuntimeError("... and the block fails before commit")
    with database.transaction(db_url) as db:
        assert db.scalars(select(PlannedNetworkRow.name)).all() == ["kept"]


def test_update_of_a_missing_plan_changes_nothing(store: PlannedNetworkStore) -> None:
    kept = store.save(plan())
    with pytest.raises(NotFound):
        store.update(kept.id + 1, plan("other"))
    assert [(s.id, s.name) for s in store.list()] == [(kept.id, "Line 1")]


def test_export_then_import_round_trips(store: PlannedNetworkStore) -> None:
    saved = store.save(plan())
    text = store.export_json(saved.id)
    assert json.loads(text)["nodes"][0]["node_id"] == 5
    again = store.import_json(text)
    assert again.id != saved.id and again.plan == saved.plan


@pytest.mark.parametrize(
    "text",
    ["{not json", '{"name": "x", "nodes": [{"device": "lenze-8400-motec", "node_id": 300, "baud_kbit": 500}]}',
     "[]", ""],
)
def test_bad_json_import_is_refused_and_nothing_is_lost(store: PlannedNetworkStore, text: str) -> None:
    kept = store.save(plan())
    with pytest.raises(InvalidValue, match="Not a network plan"):
        store.import_json(text)
    assert [s.id for s in store.list()] == [kept.id]
    assert store.get(kept.id).plan == plan()


# --- comparison with the nodes a scan found ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def profiles() -> ProfileRegistry:
    return ProfileRegistry()


def test_compare_live_names_ok_wrong_missing_extra_and_unidentified(profiles: ProfileRegistry) -> None:
    planned = NetworkPlan(nodes=[
        PlannedNode(device="lenze-8400-motec", node_id=5, baud_kbit=500),
        PlannedNode(device="lenze-8400-motec", node_id=12, baud_kbit=500),
        PlannedNode(device="lenze-emf2178ib", node_id=20, baud_kbit=500),
        PlannedNode(device="lenze-8400-motec", node_id=7, baud_kbit=500),
        PlannedNode(device="lenze-emf2178ib", node_id=9, baud_kbit=500),
    ])
    answered = [
        SessionNode(5, profiles.get("lenze-8400-motec-canopen"), identity={"vendor_id": 0x3B}),
        SessionNode(12, profiles.get("lenze-8200-vector-emf2178ib"), identity={"vendor_id": 0x3B}),
        SessionNode(20, profiles.get("lenze-93xx-emf2178ib")),
        SessionNode(9, None, identity={"vendor_id": 0x19, "product_code": 1}),
        SessionNode(30, None, identity={"vendor_id": 0x3B}),
        SessionNode(33, None),
    ]
    result = compare_live(planned, answered, shipped_switch_devices(), session_id="s", session_name="Line")
    status = {c.node_id: c.status for c in result.nodes}
    assert status == {5: "ok", 12: "wrong_device", 20: "ok", 7: "missing", 9: "wrong_device", 30: "extra",
                      33: "extra"}
    assert not result.ok
    assert result.counts == {"ok": 2, "wrong_device": 2, "unverified": 0, "missing": 1, "extra": 2}
    by_id = {c.node_id: c for c in result.nodes}
    assert "planned" in by_id[12].message and "8200" in (by_id[12].found_device or "")
    assert "0x00000019" in by_id[9].message


def test_compare_live_all_as_planned_is_ok(profiles: ProfileRegistry) -> None:
    planned = NetworkPlan(nodes=[PlannedNode(device="lenze-8400-motec", node_id=5, baud_kbit=500),
                                 PlannedNode(device="lenze-emf2178ib", node_id=6, baud_kbit=500)])
    answered = [SessionNode(5, profiles.get("lenze-8400-motec-canopen")),
                SessionNode(6, None, identity={"vendor_id": 0x3B, "product_code": 0x1234})]
    result = compare_live(planned, answered, shipped_switch_devices())
    assert [c.status for c in result.nodes] == ["ok", "unverified"]
    assert not result.ok  # a node without a matching profile is not proof of the planned device
    assert "no device profile matches" in result.nodes[1].message
    assert compare_live(NetworkPlan(nodes=planned.nodes[:1]), answered[:1], shipped_switch_devices()).ok


def test_two_start_ups_at_once_on_one_new_database(db_url: str) -> None:
    """Two servers (processes) starting together on one new database: both come up, the schema exists once."""
    import subprocess
    import sys

    url = db_url
    code = "import sys; from drivebench.services.storage import database; database.upgrade_to_head(sys.argv[1])"
    starts = [subprocess.Popen([sys.executable, "-c", code, url], stderr=subprocess.PIPE, text=True)
              for _ in range(2)]
    results = [(p.wait(timeout=60), p.stderr.read() if p.stderr else "") for p in starts]
    for p in starts:
        if p.stderr:
            p.stderr.close()
    assert results == [(0, ""), (0, "")]
    assert database.current_revision(url) is not None
    assert inspect(database.engine(url)).get_table_names().count("planned_network") == 1


def test_an_upgrade_from_the_oldest_migration_keeps_the_data_of_every_step(db_url: str) -> None:
    """A database made by the first release, used at each release in turn, upgraded to today: nothing lost."""
    from alembic import command
    from sqlalchemy import text

    database.engine(db_url)  # makes a SQLite file's folder, as a server's start-up does
    config = database.alembic_config(db_url)
    revisions = [r.revision for r in reversed(list(ScriptDirectory.from_config(config).walk_revisions()))]
    assert revisions[0] == "0001_planned_network"
    when = "2024-01-02 03:04:05+00:00"
    rows_at = {
        "0001_planned_network": ("INSERT INTO planned_network (name, created, updated, body) "
                                 "VALUES ('Line 1', :t, :t, :body)", {"body": json.dumps(plan().model_dump())}),
        "0002_parameter_sets": ("INSERT INTO audit_log (time, \"user\", session_id, node_id, ref, address, old_value, "
                                "new_value, result, detail, origin) VALUES (:t, 'anna', 'line-1', 5, 'C00012', "
                                "'0x5FF3.0', '2.00 s', '3.00 s', 'written', NULL, 'parameters')", {}),
        "0003_accounts": ("INSERT INTO user_account (name, role, password_hash, created, disabled) "
                          "VALUES ('anna', 'engineer', 'argon2-hash', :t, false)", {}),
        "0005_shared_state": ("INSERT INTO api_token (name, owner_id, role, token_hash, hint, created) "
                              "VALUES ('ci', 1, 'viewer', :h, 'dbt_abcdef', :t)", {"h": "0" * 64}),
    }
    for revision in revisions:
        command.upgrade(config, revision)
        if revision in rows_at:
            sql, values = rows_at[revision]
            with database.engine(db_url).begin() as connection:
                connection.execute(text(sql), {"t": when, **values})
    assert database.current_revision(db_url) == revisions[-1]
    database.upgrade_to_head(db_url)  # what a server does at start: nothing left to do

    networks = PlannedNetworkStore(db_url).list()
    assert [n.name for n in networks] == ["Line 1"]
    with database.engine(db_url).connect() as connection:
        audit = connection.execute(text("SELECT \"user\", ref, new_value FROM audit_log")).all()
        users = connection.execute(text("SELECT name, session_stamp FROM user_account")).all()
        tokens = connection.execute(text("SELECT name, parent_id FROM api_token")).all()
    assert [tuple(row) for row in audit] == [("anna", "C00012", "3.00 s")]
    assert [row[0] for row in users] == ["anna"] and len(users[0][1]) == 16  # 0004 gave her a session stamp
    assert [tuple(row) for row in tokens] == [("ci", None)]  # 0006: made by a signed-in user, not by a token


def test_a_start_on_a_current_schema_does_not_import_alembic(db_url: str) -> None:
    """Importing Alembic (it imports its operations and dialects) cost a server start ~0.15 s of CPU where there was
    nothing to migrate: a fresh interpreter finds the schema current without it."""
    import subprocess
    import sys

    database.upgrade_to_head(db_url)
    code = ("import sys; from drivebench.services.storage import database; database.upgrade_to_head(sys.argv[1]); "
            "print(sorted(name for name in sys.modules if name.split('.')[0] == 'alembic'))")
    done = subprocess.run([sys.executable, "-c", code, db_url], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
