"""The safety context as one explicit value (issue 29): every call that can write takes a
:class:`~drivebench.services.params.write_context.WriteContext`, with no default, so a write without one never
reaches the bus; the guard's own context can only stop; the audit row names the user and origin of the context the
write was given. Watched on the demo plant's virtual CAN bus (the ``wire`` fixture records every frame)."""

from __future__ import annotations

import asyncio
import inspect
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from types import ModuleType
from typing import Any

import can
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ConfirmationRequired
from drivebench.services.bus.sessions import Session
from drivebench.services.control import commissioning, drive_control, drive_guard, motion
from drivebench.services.monitoring import diagnostics
from drivebench.services.params import (
    node_lease,
    parameter_batch,
    parameters,
    reads,
    session_part,
    write_context,
    writes,
)
from drivebench.services.params.write_context import LOCAL_USER, SERVICE_PANEL, WriteContext, Writer
from drivebench.services.pdos import ethercat_pdo, pdo
from drivebench.services.session_manager import SessionManager
from drivebench.services.sets import set_jobs
from drivebench.services.storage import database
from drivebench.services.users import audit, undo
from drivebench.simulator.plant import Plant

SERVO, MOTEC = 7, 5
ANNA = Writer("anna", "panel:a1", "Parameters tab")
CONTROL_WORD = 0x6040
SDO_DOWNLOAD = 0x20  # client command specifier 1 (initiate download), in the top three bits

WRITES: list[Callable[..., Any]] = [
    parameters.write, parameters.send_logged, parameters.command, parameters.start_read, parameters.read_node,
    parameters.sdo_channels, parameter_batch.write_many, node_lease.writing, drive_guard.confirm_moving,
    drive_guard.admit_moving_write, drive_guard.stopped, drive_guard.write_word, drive_guard.send_quick_stop,
    drive_guard.nmt, drive_guard.send_rpdo, drive_control.command, drive_control.set_setpoint, drive_control.jog,
    drive_control.set_mode, drive_control.write_control_word, motion.move, motion.home, commissioning.next_step,
    commissioning.Wizard.start, set_jobs.start_upload, set_jobs.start_download, set_jobs.start_retry,
    set_jobs.start_rollback, set_jobs.preview, set_jobs.held_moving, set_jobs.device_source, pdo.apply_pdo,
    pdo.run_plan, ethercat_pdo.apply_mapping, undo.undo, diagnostics.write_heartbeat_producer,
    diagnostics.write_heartbeat_consumer, diagnostics.start_guarding]


@pytest.mark.parametrize("write", WRITES, ids=lambda write: write.__qualname__)
def test_every_call_that_can_write_takes_the_context_without_a_default(write: Callable[..., Any]) -> None:
    signature = inspect.signature(inspect.unwrap(write))
    assert "ctx" in signature.parameters, f"{write.__qualname__} says nothing of what its writes are checked against"
    assert signature.parameters["ctx"].default is inspect.Parameter.empty, f"{write.__qualname__}: ctx has a default"


@pytest.mark.parametrize("module", [drive_guard, node_lease, write_context, audit, session_part, reads, writes])
def test_no_safety_input_travels_in_a_context_variable(module: ModuleType) -> None:
    """The locale stays a context variable (i18n), and the read plan's own (``_urgent``, ``_snapshot``): who writes,
    from which panel, with which confirmation and lease travels only in the WriteContext."""
    hidden = sorted(name for name, value in vars(module).items() if isinstance(value, ContextVar)
                    and name not in ("_urgent", "_snapshot"))
    assert hidden == [], f"{module.__name__} keeps safety inputs in context variables: {hidden}"


def _downloads(wire: can.BusABC, node_id: int, index: int) -> list[bytes]:
    """The SDO download requests to ``index`` of the node seen on the wire since the last look."""
    seen: list[bytes] = []
    while (msg := wire.recv(timeout=0.2)) is not None:
        data = bytes(msg.data)
        if (msg.arbitration_id == 0x600 + node_id and len(data) == 8 and data[0] & 0xE0 == SDO_DOWNLOAD
                and int.from_bytes(data[1:3], "little") == index):
            seen.append(data)
    return seen


def test_a_write_without_a_context_never_reaches_the_bus(plant_session: tuple[asyncio.Runner, Session],
                                                         wire: can.BusABC) -> None:
    runner, session = plant_session
    with pytest.raises(TypeError, match="ctx"):
        runner.run(parameters.write(session, SERVO, "0x6040", 0x000F, verify=False))  # type: ignore[call-arg]
    assert _downloads(wire, SERVO, CONTROL_WORD) == [], "a write without a context was sent"


def test_the_guards_stop_context_sends_a_still_word_and_never_a_moving_one(
        plant_session: tuple[asyncio.Runner, Session], wire: can.BusABC) -> None:
    runner, session = plant_session
    held = WriteContext.request(user="anna", origin="parameters", panel=SERVICE_PANEL, writer=ANNA, confirmation=None)
    runner.run(parameters.write(session, SERVO, "0x6060", 3, ctx=held.cleared_by_caller(), verify=False))
    _downloads(wire, SERVO, CONTROL_WORD)  # anna holds the node's lease from here on
    assert node_lease.leases(session).current(SERVO) is not None
    stop = WriteContext.guard_stop()
    with pytest.raises(ConfirmationRequired):  # enable operation: the guard's context confirms nothing
        runner.run(parameters.write(session, SERVO, "0x6040", 0x000F, ctx=stop, verify=False))
    assert _downloads(wire, SERVO, CONTROL_WORD) == [], "the guard's stop context sent a word that can move"
    runner.run(parameters.write(session, SERVO, "0x6040", 0x0002, ctx=stop, verify=False))  # quick stop
    sent = _downloads(wire, SERVO, CONTROL_WORD)
    assert [int.from_bytes(data[4:6], "little") for data in sent] == [0x0002], "the stop goes out past the lease"


@pytest.fixture
def audited(registry: ProfileRegistry, plant: Plant, database_url: str) -> Iterator[tuple[asyncio.Runner, Session,
                                                                                          str]]:
    database.upgrade_to_head(database_url)
    runner = asyncio.Runner()
    manager = SessionManager(registry, sdo_timeout_s=1.0, sdo_retries=1, write_audits=[audit.AuditLog(database_url)])
    session = runner.run(manager.open(plant.spec, "write-context"))
    for node in plant.nodes.values():
        session.add_node(node.node_id, node.profile.id)
    try:
        yield runner, session, database_url
    finally:
        runner.run(manager.close_all())
        runner.close()


def test_the_audit_row_names_the_user_and_origin_of_the_context_given(
        audited: tuple[asyncio.Runner, Session, str]) -> None:
    runner, session, url = audited
    anna = WriteContext.request(user="anna", origin="commissioning", panel=SERVICE_PANEL, writer=ANNA,
                                confirmation=None)
    runner.run(parameters.write(session, MOTEC, "C00039/1", 15, ctx=anna, verify=False))
    ben = WriteContext.internal(user="ben", origin="pdo")
    runner.run(parameters.send_logged(session, MOTEC, 0x1017, 0, (0).to_bytes(2, "little"), ctx=ben))
    runner.run(parameters.write(session, MOTEC, "C00039/1", 14, ctx=anna.as_origin("undo 1"), verify=False))
    rows = [(row.user, row.origin, row.ref) for row in reversed(audit.entries(url, node_id=MOTEC))]
    assert rows == [("anna", "commissioning", "C00039/1"), ("ben", "pdo", "0x1017"), ("anna", "undo 1", "C00039/1")]
    assert LOCAL_USER not in {user for user, _origin, _ref in rows}, "no write falls back to the process's user"
