"""Parameter sets against simulated drives on a real virtual bus, stored in a temporary SQLite file through the
package's migrations: upload, every file format there and back, compare views, download with a device that refuses
values mid-way (report, retry, rollback), copy to a second identical axis, history, and the audit log."""

from __future__ import annotations

import asyncio
import json
import signal
import subprocess
import sys
import time
from collections.abc import Coroutine, Iterator
from pathlib import Path
from typing import Any, TypeVar

import pytest
from sqlalchemy import text

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ConfirmationRequired, Conflict, DriveBenchError, NotFound, OutOfRange
from drivebench.services.bus.sessions import Session
from drivebench.services.params import parameters
from drivebench.services.params.jobs import Job, JobManager, JobState
from drivebench.services.session_manager import SessionManager
from drivebench.services.sets import set_formats, set_jobs
from drivebench.services.sets.parameter_sets import (
    ParameterSetStore,
    StoredSet,
    compare,
    comparison_csv,
    defaults_source,
    retarget,
    set_source,
)
from drivebench.services.storage import database
from drivebench.services.users import audit
from drivebench.simulator.plant import Plant, PlantFile
from drivebench.simulator.store import Abort
from tests.confirming import confirmed_now
from tests.write_contexts import SERVICE

T = TypeVar("T")
PLANT = {"name": "Set test plant", "nodes": [
    {"node_id": 2, "profile": "lenze-8400-motec-canopen"},
    {"node_id": 3, "profile": "siemens-micromaster4-canopen"},
    {"node_id": 5, "profile": "lenze-8400-motec-canopen"},
    {"node_id": 12, "profile": "lenze-8200-vector-emf2178ib"},
]}


class Bench:
    def __init__(self, runner: asyncio.Runner, session: Session, plant: Plant, store: ParameterSetStore,
                 url: str) -> None:
        self.runner, self.session, self.plant, self.store, self.url = runner, session, plant, store, url
        self.jobs = JobManager()

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        return self.runner.run(coro)

    def finish(self, start: Any) -> Job:
        async def go() -> Job:
            job: Job = start()
            await job.wait()
            return job
        return self.run(go())

    def upload(self, node_id: int, name: str = "set") -> StoredSet:
        job = self.finish(lambda: set_jobs.start_upload(self.session, node_id, self.jobs, self.store, name=name,
                                                        user="tester", ctx=SERVICE))
        assert job.state is JobState.DONE, job.error
        return self.store.get(job.result["set_id"])

    def device(self, node_id: int, ref: str) -> Any:
        return self.plant.nodes[node_id].store.get_ref(ref)


@pytest.fixture
def db_url(database_url: str) -> str:
    """Each test on a new SQLite file and again on a new PostgreSQL database."""
    database.upgrade_to_head(database_url)
    return database_url


@pytest.fixture
def bench(registry: ProfileRegistry, channel: str, db_url: str) -> Iterator[Bench]:
    plant = Plant(PlantFile.model_validate(PLANT), registry.get, bus=f"virtual:{channel}@500000",
                  latency="0ms").start()
    runner = asyncio.Runner()
    manager = SessionManager(registry, sdo_timeout_s=1.0, sdo_retries=1,  # a loaded CI machine is slow
                             write_audits=[audit.AuditLog(db_url)])
    session = runner.run(manager.open(plant.spec, "sets"))
    for node in PLANT["nodes"]:
        session.add_node(node["node_id"], node["profile"])  # type: ignore[arg-type]
    try:
        yield Bench(runner, session, plant, ParameterSetStore(db_url), db_url)
    finally:
        runner.run(manager.close_all())
        runner.close()
        plant.stop()


# --- upload and formats -----------------------------------------------------------------------------------
@pytest.mark.parametrize("node_id", [5, 12, 3])
@pytest.mark.parametrize("fmt", ["json", "csv", "dcf"])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_every_format_round_trips(bench: Bench, registry: ProfileRegistry, node_id: int, fmt: str) -> None:
    stored = bench.upload(node_id, f"node {node_id}")
    profile = registry.get(stored.info.profile_id)
    assert len(stored.values) > 20
    assert "C00002/11" not in stored.values and "0x1010.1" not in stored.values  # commands are not settings
    text, _ = set_formats.export(fmt, stored, profile)
    if fmt == "json":
        again = set_formats.import_json(text, registry.get)
    elif fmt == "csv":
        again = set_formats.import_csv(text, registry.get)
    else:
        again = set_formats.import_dcf(text, registry.get)
    assert again.profile.id == profile.id
    assert again.values == stored.values
    assert list(again.values) == list(stored.values)


def test_json_file_carries_profile_id_version_and_scaled_values(bench: Bench, registry: ProfileRegistry) -> None:
    bench.run(parameters.write(bench.session, 5, "C00088", "10.20 A", ctx=SERVICE))
    stored = bench.upload(5, "Conveyor")
    text = set_formats.export_json(stored, registry.get("lenze-8400-motec-canopen"))
    document = json.loads(text)
    assert (document["schema"], document["profile_id"], document["profile_version"]) == \
        ("drivebench.parameter-set/1", "lenze-8400-motec-canopen", "1")
    c88 = next(p for p in document["parameters"] if p["ref"] == "C00088")
    assert (c88["value"], c88["unit"], c88["raw"]) == (10.2, "A", 1020)


def test_imports_name_every_line_that_does_not_fit(bench: Bench, registry: ProfileRegistry) -> None:
    stored = bench.upload(5, "Conveyor")
    profile = registry.get("lenze-8400-motec-canopen")
    lines = set_formats.export_json(stored, profile).splitlines()
    c324 = next(n for n, line in enumerate(lines) if '"ref": "C00324/1"' in line)
    lines[c324] = '  {"ref": "C00324/1", "value": 9999},'
    lines.insert(c324 + 1, '  {"ref": "C99999", "value": 1},')
    with pytest.raises(set_formats.SetImportError) as caught:
        set_formats.import_json("\n".join(lines), registry.get, source="conveyor.json")
    assert [(e.line, e.ref) for e in caught.value.errors] == [(c324 + 1, "C00324/1"), (c324 + 2, "C99999")]
    assert "outside the allowed range 0 ... 6500 ms" in caught.value.errors[0].detail
    assert "line 16" not in caught.value.detail or "conveyor.json" in caught.value.detail

    csv_text = set_formats.export_csv(stored, profile).splitlines()
    row = next(n for n, line in enumerate(csv_text) if line.startswith("C00088,"))
    csv_text[row] = "C00088,Rated motor current,ten,A"
    with pytest.raises(set_formats.SetImportError) as caught_csv:
        set_formats.import_csv("\n".join(csv_text), registry.get)
    assert [(e.line, e.ref) for e in caught_csv.value.errors] == [(row + 1, "C00088")]
    assert "expects a number" in caught_csv.value.errors[0].detail

    dcf = set_formats.export_dcf(stored, profile).splitlines()
    section = dcf.index("[5FA7]")
    value_line = next(n for n in range(section, len(dcf)) if dcf[n].startswith("ParameterValue="))
    dcf[value_line] = "ParameterValue=0xFFFFFFFFF"
    with pytest.raises(set_formats.SetImportError) as caught_dcf:
        set_formats.import_dcf("\n".join(dcf), registry.get)
    assert [(e.line, e.ref) for e in caught_dcf.value.errors] == [(value_line + 1, "C00088")]
    assert bench.store.all() and len(bench.store.all()) == 1  # nothing stored by the refused imports


# --- store ----------------------------------------------------------------------------------------------
def test_history_rename_delete(bench: Bench, registry: ProfileRegistry) -> None:
    stored = bench.upload(5, "Conveyor")
    changed = dict(stored.values, C00088=800)
    bench.store.update_values(stored.info.id, changed, user="anna", reason="edited C00088")
    renamed = bench.store.rename(stored.info.id, "Conveyor (line 2)", note="after the gearbox change")
    assert (renamed.name, renamed.note, renamed.version) == ("Conveyor (line 2)", "after the gearbox change", 2)
    assert [(v.version, v.reason) for v in bench.store.history(stored.info.id)] == \
        [(2, "edited C00088"), (1, "upload from node 5")]
    assert bench.store.get(stored.info.id, version=1).values == stored.values
    assert bench.store.get(stored.info.id).values["C00088"] == 800
    bench.store.delete(stored.info.id)
    with pytest.raises(NotFound):
        bench.store.get(stored.info.id)
    assert bench.store.all() == []


# --- compare -----------------------------------------------------------------------------------------------
def test_compare_device_vs_set_set_vs_set_and_defaults(bench: Bench, registry: ProfileRegistry) -> None:
    profile = registry.get("lenze-8400-motec-canopen")
    stored = bench.upload(5, "Conveyor")
    bench.plant.nodes[5].store.set_ref("C00088", 750)   # someone changed the drive: 7.50 A
    device = bench.run(set_jobs.device_source(bench.session, 5, ctx=SERVICE))
    result = compare(device, set_source(stored, profile))
    assert [(r.ref, r.left, r.right, r.unit, r.kind) for r in result.rows] == \
        [("C00088", "7.50 A", stored_display(stored, "C00088"), "A", "changed")]
    assert result.equal == result.compared - 1

    c88, c11 = stored.values["C00088"], stored.values["C00011"]
    assert isinstance(c88, int) and isinstance(c11, int)
    second = bench.store.create("Other", profile, dict(stored.values, C00088=c88 + 100, C00011=c11 + 10), user="t")
    both = compare(set_source(stored, profile), set_source(second, profile))
    assert [(r.ref, r.kind) for r in both.rows] == [("C00011", "changed"), ("C00088", "changed")]
    assert both.rows[1].left == stored_display(stored, "C00088") and both.rows[1].unit == "A"
    filtered = compare(set_source(stored, profile), set_source(second, profile), query="motor current")
    assert [r.ref for r in filtered.rows] == ["C00088"]
    text = comparison_csv(filtered)
    assert text.splitlines()[0].startswith("code,name,unit,") and "C00088" in text

    defaults = defaults_source(profile, 5)
    assert defaults.values["C00088"] == c88  # the simulated drive starts at the profile's defaults
    bench.store.update_values(stored.info.id, dict(stored.values, C00088=c88 + 100), user="t", reason="x")
    against_defaults = compare(set_source(bench.store.get(stored.info.id), profile), defaults)
    assert "C00088" in [r.ref for r in against_defaults.rows]
    assert [r.ref for r in compare(set_source(stored, profile), defaults).rows] == []
    with pytest.raises(Conflict):
        compare(device, defaults_source(registry.get("lenze-8200-vector-emf2178ib")))


def stored_display(stored: StoredSet, ref: str) -> str:
    raw = stored.values[ref]
    assert isinstance(raw, int)
    return f"{raw / 100:.2f} A"


# --- download ----------------------------------------------------------------------------------------------
def test_download_meets_read_only_and_out_of_range_mid_way_then_retry_and_rollback(bench: Bench,
                                                                                  registry: ProfileRegistry) -> None:
    profile = registry.get("lenze-8400-motec-canopen")
    node = bench.plant.nodes[5].store
    bench.upload(5, "as found")
    # The set changes five parameters; mid-way the device refuses two (read-only now, too high for this device)
    # and one stored value is outside the profile's range (refused before sending).
    changes = {"C00088": 1250, "C00011": 1450, "C00324/1": 5000, "C00356/1": 70000, "C00039/1": 5000}
    current = {ref: node.get_ref(ref) for ref in changes}
    wanted = dict(bench.upload(5, "base").values, **changes)
    new_set = bench.store.create("commissioned", profile, wanted, user="anna")
    c11, c324 = (node.catalog.resolve(r) for r in ("C00011", "C00324/1"))

    def refuse(index: int, sub: int, raw: object) -> None:
        if (index, sub) == (c11.index, c11.subindex):
            raise Abort(0x06010002)  # read-only (e.g. only while the controller is inhibited)
        if (index, sub) == (c324.index, c324.subindex):
            raise Abort(0x06090031)  # value too high for this device
    node.add_write_check(refuse)
    before = dict(current)

    preview = bench.run(set_jobs.preview(bench.session, 5, new_set, ctx=SERVICE))
    assert [line.ref for line in preview] == ["C00011", "C00039/1", "C00088", "C00324/1", "C00356/1"]
    assert next(line for line in preview if line.ref == "C00088").target == "12.50 A"

    with pytest.raises(ConfirmationRequired, match="C00007"):  # the set holds the control mode (a command source)
        set_jobs.start_download(bench.session, 5, bench.jobs, bench.store, new_set, ctx=SERVICE)
    job = bench.finish(lambda: confirmed_now(set_jobs.start_download, bench.session, 5, bench.jobs, bench.store,
                                             new_set, save=True, confirm=5, ctx=SERVICE))
    assert job.state is JobState.INCOMPLETE  # three values did not go in (issue 28 item 5)
    report = {line["ref"]: line for line in job.result["report"]}
    assert len(report) == len(wanted)
    assert report["C00011"]["status"] == "failed" and report["C00011"]["abort_code"] == "0x06010002"
    assert report["C00324/1"]["status"] == "failed" and report["C00324/1"]["abort_code"] == "0x06090031"
    assert report["C00356/1"]["status"] == "failed" and "not sent" in report["C00356/1"]["detail"]
    assert report["C00011"]["now_raw"] == before["C00011"]  # read again: what the device holds now
    for ref in ("C00088", "C00039/1"):
        assert report[ref]["status"] == "written" and node.get_ref(ref) == changes[ref]
    others = {ref: (line["status"], line["detail"]) for ref, line in report.items() if ref not in changes}
    assert {status for status, _ in others.values()} == {"unchanged"}, \
        {ref: v for ref, v in others.items() if v[0] != "unchanged"}
    assert job.result["state"] == "incomplete" and "saved" not in job.result
    assert any("Not saved" in note for note in job.notes)
    download = bench.store.download(job.result["download_id"])
    assert download.state == "incomplete" and download.before["C00088"] == before["C00088"]

    logged = audit.entries(bench.url, node_id=5)
    origin = f"download {job.result['download_id']}"
    assert sorted((e.ref, e.result) for e in logged if e.origin == origin) == \
        [("C00011", "failed"), ("C00039/1", "written"), ("C00088", "written"), ("C00324/1", "failed")]

    node._checks.clear()  # the drive now accepts them: retry the failed ones (the profile still refuses one)
    retry = bench.finish(lambda: set_jobs.start_retry(bench.session, bench.jobs, bench.store,
                                                      job.result["download_id"], ctx=SERVICE))
    assert {line["ref"]: line["status"] for line in retry.result["report"]} == \
        {"C00011": "written", "C00324/1": "written", "C00356/1": "failed"}
    assert (node.get_ref("C00011"), node.get_ref("C00324/1")) == (1450, 5000)

    back = bench.finish(lambda: set_jobs.start_rollback(bench.session, bench.jobs, bench.store,
                                                        job.result["download_id"], ctx=SERVICE))
    assert back.state is JobState.DONE
    assert {ref: node.get_ref(ref) for ref in before} == before


def test_download_to_a_node_of_another_type_is_refused(bench: Bench) -> None:
    stored = bench.upload(12, "fan")
    with pytest.raises(Conflict, match="8200"):
        bench.run(set_jobs.preview(bench.session, 5, stored, ctx=SERVICE))


def test_copy_to_a_second_identical_axis(bench: Bench, registry: ProfileRegistry) -> None:
    profile = registry.get("lenze-8400-motec-canopen")
    bench.run(parameters.write(bench.session, 5, "C00088", "12.50 A", ctx=SERVICE))
    bench.run(parameters.write(bench.session, 5, "C00350", 5, ctx=SERVICE))
    source = bench.upload(5, "axis 1")
    values, notes = retarget(profile, source.values, 5, 2)
    assert values["C00350"] == 2 and any("C00350" in note for note in notes)
    copy = bench.store.create("axis 2", profile, values, user="t", node_id=2, reason="copy of set 1 for node 2")
    job = bench.finish(lambda: confirmed_now(set_jobs.start_download, bench.session, 2, bench.jobs, bench.store, copy,
                                             confirm=2, ctx=SERVICE))
    assert job.result["state"] == "done"
    statuses = {line["ref"]: line["status"] for line in job.result["report"]}
    assert statuses["C00088"] == "written" and statuses["C00350"] in ("written", "unchanged")
    order = [line["ref"] for line in job.result["report"]]
    assert order.index("C00350") > order.index("C00088")  # communication parameters that need a reset last
    device = bench.run(set_jobs.device_source(bench.session, 2, ctx=SERVICE))
    assert compare(device, set_source(copy, profile)).rows == []


# --- audit log -----------------------------------------------------------------------------------------------
def test_single_writes_are_audited_with_old_and_new_value(bench: Bench) -> None:
    bench.run(parameters.read(bench.session, 5, "C00088"))
    bench.run(parameters.write(bench.session, 5, "C00088", "12.50 A", ctx=SERVICE))
    with pytest.raises(OutOfRange):
        bench.run(parameters.write(bench.session, 5, "C00324/1", 9999,
                                   ctx=SERVICE))  # refused before sending: not a write
    entry = audit.entries(bench.url)[0]
    assert (entry.ref, entry.node_id, entry.new_value, entry.result, entry.origin) == \
        ("C00088", 5, "12.50 A", "written", "parameters")
    assert entry.old_value is not None and entry.user
    assert len(audit.entries(bench.url)) == 1
    assert audit.to_csv(audit.entries(bench.url)).splitlines()[1].split(",")[4] == "C00088"


# --- kill during a download or an import ---------------------------------------------------------------------
KILLED_DOWNLOAD = """
import asyncio, sys
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.users import audit
from drivebench.errors import ConfirmationRequired
from drivebench.services.control.drive_guard import Confirmation
from drivebench.services.params.write_context import LOCAL_USER, WriteContext
from drivebench.services.sets import set_jobs
from drivebench.services.params.jobs import JobManager
from drivebench.services.sets.parameter_sets import ParameterSetStore
from drivebench.services.session_manager import SessionManager
from drivebench.simulator.plant import Plant, PlantFile

url, set_id = sys.argv[1], int(sys.argv[2])
SERVICE = WriteContext.internal(user=LOCAL_USER, origin="parameters")
registry = ProfileRegistry()
nodes = [{"node_id": 5, "profile": "lenze-8400-motec-canopen"}]
plant_file = PlantFile.model_validate({"name": "kill", "nodes": nodes})
plant = Plant(plant_file, registry.get, bus="virtual:kill@500000", latency="25ms").start()


async def main() -> None:
    manager = SessionManager(registry, sdo_timeout_s=3, sdo_retries=0, write_audits=[audit.AuditLog(url)])
    session = await manager.open(plant.spec, "kill")
    session.add_node(5, "lenze-8400-motec-canopen")
    store = ParameterSetStore(url)
    try:  # answered as a careful client does: the node and values the refusal names
        job = set_jobs.start_download(session, 5, JobManager(), store, store.get(set_id), ctx=SERVICE)
    except ConfirmationRequired as asked:
        job = set_jobs.start_download(session, 5, JobManager(), store, store.get(set_id),
                                      confirm=Confirmation(asked.node, asked.values), ctx=SERVICE)
    await job.wait()
    print("finished", job.state, flush=True)

asyncio.run(main())
"""

KILLED_IMPORT = """
import sys
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.sets.parameter_sets import ParameterSetStore

url = sys.argv[1]
profile = ProfileRegistry().get("lenze-8400-motec-canopen")
store = ParameterSetStore(url)
values = {f"C{n:05d}": n for n in range(5000)}
for number in range(10_000):
    store.create(f"bulk {number}", profile, values, user="bulk")
    print(number, flush=True)
"""


def _changed_values(profile: Any) -> dict[str, Any]:
    """The profile's defaults with every ordinary numeric setting moved by one step (still in range)."""
    from drivebench.services.sets.parameter_sets import catalog_for, defaults_of, engineering

    catalog = catalog_for(profile)
    values = defaults_of(profile, 5)
    for ref, raw in list(values.items()):
        item = catalog.resolve(ref)
        entry = item.entry
        if not isinstance(raw, int) or entry.reset_required or 0x1000 <= item.index <= 0x1FFF or entry.selection \
                or entry.bits:
            continue
        try:
            set_formats._raw_for(item, engineering(item, raw + 1))
        except DriveBenchError:  # not every setting has room above its default
            continue
        values[ref] = raw + 1
    return values


def _wait_for(predicate: Any, process: Any, deadline_s: float, what: str) -> None:
    end = time.monotonic() + deadline_s
    while not predicate():
        assert process.poll() is None, f"the child ended before it was killed: {process.stdout.read()}"
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.02)


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_kill_during_download_loses_nothing_and_shows_interrupted(registry: ProfileRegistry, db_url: str,
                                                                  tmp_path: Path) -> None:
    from drivebench.services.params.jobs import JobManager
    from drivebench.services.sets.set_jobs import download_state

    profile = registry.get("lenze-8400-motec-canopen")
    store = ParameterSetStore(db_url)
    kept = store.create("kept", profile, {"C00088": 1020, "C00011": 1500}, user="t")
    store.update_values(kept.info.id, {"C00088": 1100, "C00011": 1500}, user="t", reason="edited")
    target = store.create("many changes", profile, _changed_values(profile), user="t")
    changes = sum(1 for ref, raw in target.values.items() if raw != defaults_source(profile, 5).values.get(ref))
    assert changes > 15

    script = tmp_path / "download.py"
    script.write_text(KILLED_DOWNLOAD)
    child = subprocess.Popen([sys.executable, str(script), db_url, str(target.info.id)], stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    try:
        _wait_for(lambda: sum(e.result == "written" and e.origin.startswith("download ")
                              for e in audit.entries(db_url)) >= 3, child, 60,
                  "three verified writes")
        child.send_signal(signal.SIGKILL)
        child.wait(10)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(10)

    # nothing stored is lost: the sets and their history, and the values read before the first write
    assert store.get(kept.info.id, version=1).values == {"C00088": 1020, "C00011": 1500}
    assert store.get(kept.info.id).values == {"C00088": 1100, "C00011": 1500}
    assert store.get(target.info.id).values == target.values
    [download] = store.downloads()
    assert download.state == "running" and download.report == []
    assert download_state(download, JobManager()) == "interrupted"
    assert set(download.before) == set(target.values)  # every value it would touch, read before writing
    logged = audit.entries(db_url)
    switched = [e for e in logged if e.origin == "download"]  # SDO2 switched on while the values were read first
    assert sorted(e.address for e in switched) == ["0x1201sub1", "0x1201sub2"]
    logged = [e for e in logged if e.origin != "download"]
    assert {e.result for e in logged} <= {"written", "sending"}
    assert sum(e.result == "sending" for e in logged) <= 1  # at most the write under way when it was killed
    assert all(e.origin == f"download {download.id}" for e in logged)
    with database.transaction(db_url) as db:
        if db_url.startswith("sqlite"):
            assert db.execute(text("PRAGMA integrity_check")).scalar() == "ok"
        else:  # the server rolled back the killed writer's open transaction: nothing of it is left holding locks
            open_elsewhere = ("SELECT count(*) FROM pg_stat_activity WHERE datname = current_database() "
                              "AND pid <> pg_backend_pid() AND state LIKE 'idle in transaction%'")
            assert db.execute(text(open_elsewhere)).scalar() == 0


@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_kill_during_imports_leaves_only_whole_sets(registry: ProfileRegistry, db_url: str, tmp_path: Path) -> None:
    script = tmp_path / "imports.py"
    script.write_text(KILLED_IMPORT)
    child = subprocess.Popen([sys.executable, str(script), db_url], stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    store = ParameterSetStore(db_url)
    try:
        _wait_for(lambda: len(store.all()) >= 3, child, 60, "three stored sets")
        child.send_signal(signal.SIGKILL)
        child.wait(10)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(10)
    stored = store.all()
    assert len(stored) >= 3
    for info in stored:  # each set is whole: its row, its version and all 5,000 values, or nothing
        assert info.count == 5000 and len(store.get(info.id).values) == 5000


def test_an_edit_of_a_version_that_is_no_longer_current_is_refused_naming_who_changed_it(
        registry: ProfileRegistry, db_url: str) -> None:
    profile = registry.get("lenze-8400-motec-canopen")
    store = ParameterSetStore(db_url)
    stored = store.create("Conveyor", profile, {"C00088": 1020, "C00011": 1500}, user="eve")
    store.update_values(stored.info.id, {"C00088": 1100, "C00011": 1500}, user="anna", reason="edited",
                        base_version=1)
    with pytest.raises(Conflict) as stale:
        store.update_values(stored.info.id, {"C00088": 1200, "C00011": 1500}, user="eve", reason="edited",
                            base_version=1)
    assert f"Parameter set {stored.info.id} 'Conveyor' was changed by anna at " in stale.value.detail
    assert "it is now version 2, and your change was made to version 1. Nothing was saved." in stale.value.detail
    with pytest.raises(Conflict, match="changed by anna"):
        store.rename(stored.info.id, "Conveyor 2", base_version=1)
    assert store.get(stored.info.id).values["C00088"] == 1100 and store.get(stored.info.id).info.name == "Conveyor"
    assert store.rename(stored.info.id, "Conveyor 2", base_version=2).name == "Conveyor 2"
    assert store.update_values(stored.info.id, {"C00088": 1200}, user="eve", reason="x").version == 3  # unchecked
