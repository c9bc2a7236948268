"""A wizard step's claim in the database (``services/line/wizard_claim.py``), on a SQLite file and on PostgreSQL:
requests racing for one step (threads of one process, each with its own connection, as two servers' requests are)
give it to exactly one; a lease that ran out, or a holder process of this machine that has ended, frees the step and
the step reads interrupted; a holder whose claim was taken over keeps no result; a change made outside a step is
refused while a step runs."""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import pytest

from drivebench.errors import Conflict
from drivebench.services.line.wizard_run import WizardRun, WizardStore
from drivebench.services.storage import database
from drivebench.services.storage.models import LineWizardRow
from drivebench.services.storage.server_process import SERVER

RACERS = 8


@pytest.fixture
def db_url(database_url: str) -> str:
    database.upgrade_to_head(database_url)
    return database_url


def _new_run(store: WizardStore) -> WizardRun:
    return store.create(WizardRun(session_id="new-line", project_id=None, project_name="New line", created_by="eve"))


def _running(store: WizardStore, run: WizardRun, step: str, token: str) -> WizardRun:
    run = store.get(run.id)
    run.step(step).state = "running"
    return store.save_claimed(run, step, token)


def test_requests_racing_for_one_step_give_it_to_exactly_one(db_url: str) -> None:
    run = _new_run(WizardStore(db_url))
    start = threading.Barrier(RACERS)
    won: list[str] = []
    refused: list[str] = []
    failed: list[BaseException] = []

    def race() -> None:
        store = WizardStore(db_url, lease_s=60)
        start.wait()
        try:
            won.append(store.claim(run.id, "scan"))
        except Conflict as exc:
            refused.append(str(exc.detail))
        except BaseException as exc:  # a database error: a failure of the claim, reported below
            failed.append(exc)

    threads = [threading.Thread(target=race) for _ in range(RACERS)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(120)
    assert not failed, failed
    assert len(won) == 1, (won, refused)
    assert len(refused) == RACERS - 1
    assert all("is running" in detail for detail in refused)
    claim = WizardStore(db_url).get(run.id).claim
    assert claim is not None and claim.step == "scan" and claim.server == SERVER


def test_a_lease_that_ran_out_frees_the_step_which_reads_interrupted(db_url: str) -> None:
    short = WizardStore(db_url, lease_s=1.0)
    run = _new_run(short)
    token = short.claim(run.id, "assign")
    _running(short, run, "assign", token)
    with pytest.raises(Conflict, match="is running"):
        WizardStore(db_url).claim(run.id, "store")
    assert short.renew(run.id, token)
    assert short.get(run.id).steps["assign"].state == "running"

    deadline = time.monotonic() + 30
    while short.get(run.id).claim is not None:  # nobody renews it now
        assert time.monotonic() < deadline, "the lease did not run out"
        time.sleep(0.1)
    seen = short.get(run.id)
    assert seen.steps["assign"].state == "interrupted"
    assert "The server stopped while this step ran: run it again." in seen.steps["assign"].lines

    other = WizardStore(db_url, lease_s=60)
    taken = other.claim(run.id, "assign")
    assert not short.renew(run.id, token)  # the old holder does not get it back
    late = short.get(run.id)
    late.step("assign").state = "done"
    with pytest.raises(Conflict, match="ran out while the step ran"):
        short.save_claimed(late, "assign", token, release=True)
    assert other.get(run.id).claim is not None
    finished = _running(other, run, "assign", taken)
    finished.step("assign").state = "done"
    kept = other.save_claimed(finished, "assign", taken, release=True)
    assert kept.claim is None and kept.steps["assign"].state == "done"  # the new holder's result


def test_a_change_outside_a_step_is_refused_while_a_step_runs(db_url: str) -> None:
    store = WizardStore(db_url, lease_s=60)
    run = _new_run(store)
    token = store.claim(run.id, "program")
    changed = store.get(run.id)
    changed.assignments = {20: "0x000003E9"}
    with pytest.raises(Conflict, match="Program download"):
        store.save(changed)
    store.release(run.id, token)
    assert store.save(changed).assignments == {20: "0x000003E9"}


def test_the_claim_of_an_ended_process_of_this_machine_holds_no_more(db_url: str) -> None:
    store = WizardStore(db_url, lease_s=600)
    run = _new_run(store)
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                           check=True)
    host = SERVER.rpartition(":")[0]
    now = time.time()
    with database.transaction(db_url) as db:
        row = db.get(LineWizardRow, run.id)
        assert row is not None
        row.step_claim, row.step_name, row.step_server = "0" * 32, "store", f"{host}:{ended.stdout.strip()}"
        row.step_since, row.step_lease_until = now, now + 600
        row.body = {**row.body, "steps": {**row.body["steps"], "store": {"state": "running", "runs": 1}}}
    seen = store.get(run.id)
    assert seen.claim is None
    assert seen.steps["store"].state == "interrupted"
    assert store.claim(run.id, "store")
