"""Per-node write lease on the simulated demo plant: the first writer holds the node, a second one is refused with
the holder's name, never interleaved (checked on the wire); the holder writes freely; expiry, release and an admin
break free the node; an operation in progress keeps the lease; stopping is never refused."""

from __future__ import annotations

import asyncio
import contextvars

import can
import pytest

from drivebench.services.bus.sessions import Session
from drivebench.services.params import node_lease, parameters
from drivebench.services.params.node_lease import NodeLeased, Writer
from tests.write_contexts import as_writer

MOTEC = 5
ANNA = Writer("anna", "panel:a1", "Parameters tab")
BEN = Writer("ben", "panel:b2", "Parameters tab")
SDO_RX = 0x600 + MOTEC
REF, INDEX, SUB = "C00039/1", 0x5FFF - 39, 1  # Fixed setpoint-JOG1, INTEGER16, factor 100 (%)


@pytest.fixture
def bench(plant_session: tuple[asyncio.Runner, Session]) -> tuple[asyncio.Runner, Session]:
    return plant_session


async def _write_as(writer: Writer | None, session: Session, ref: str, value: object) -> parameters.WriteResult:
    return await parameters.write(session, MOTEC, ref, value, ctx=as_writer(writer), verify=False)


def _as(writer: Writer | None, session: Session, ref: str, value: object) -> asyncio.Task[parameters.WriteResult]:
    """A write in its own context, as each request runs in its own."""
    return asyncio.get_running_loop().create_task(_write_as(writer, session, ref, value),
                                                  context=contextvars.Context())


def test_second_writer_is_refused_with_the_holders_name(bench: tuple[asyncio.Runner, Session]) -> None:
    runner, session = bench

    async def scenario() -> None:
        await _as(ANNA, session, REF, 15)
        await _as(ANNA, session, REF, 14)  # the holder writes freely
        with pytest.raises(NodeLeased) as refused:
            await _as(BEN, session, REF, 10)
        text = refused.value.detail
        assert text.startswith("Node 5 is being written by anna (since ") and "Parameters tab" in text
        assert "writes are refused until anna finishes or the lease expires in" in text
        assert refused.value.extra()["holder"] == "anna"
        with pytest.raises(NodeLeased):
            await _as(None, session, REF, 10)  # a write without a writer respects the lease too
        assert (await parameters.read(session, MOTEC, REF)).value == 14
        await parameters.write(session, 12, "C0012", 20, ctx=as_writer(BEN), verify=False)  # another node is free

    runner.run(scenario())


def test_concurrent_writers_never_interleave_on_the_wire(bench: tuple[asyncio.Runner, Session], wire: can.BusABC
                                                         ) -> None:
    """Anna and Ben each fire 6 writes at once; the wire shows only one writer's SDO downloads to node 5."""
    runner, session = bench
    values = {ANNA: 12.01, BEN: 13.02}

    async def scenario() -> list[BaseException | parameters.WriteResult]:
        tasks = [_as(writer, session, REF, values[writer]) for _ in range(6) for writer in (ANNA, BEN)]
        return await asyncio.gather(*tasks, return_exceptions=True)

    results = runner.run(scenario())
    refused = [r for r in results if isinstance(r, NodeLeased)]
    done = [r for r in results if isinstance(r, parameters.WriteResult)]
    assert len(done) == 6 and len(refused) == 6, results
    winner = refused[0].lease.writer
    assert all(r.lease.writer == winner for r in refused)
    sent = []
    while (msg := wire.recv(timeout=0.2)) is not None:
        is_download = msg.arbitration_id == SDO_RX and msg.data[0] & 0xE0 == 0x20  # initiate download
        if is_download and int.from_bytes(msg.data[1:3], "little") == INDEX and msg.data[3] == SUB:
            sent.append(int.from_bytes(msg.data[4:6], "little"))
    assert len(sent) == 6 and set(sent) == {round(values[winner] * 100)}, f"downloads on the wire: {sent}"


def test_expiry_release_and_admin_break(bench: tuple[asyncio.Runner, Session], monkeypatch: pytest.MonkeyPatch
                                        ) -> None:
    runner, session = bench
    table = node_lease.leases(session)
    runner.run(_write_as(ANNA, session, REF, 15))
    assert table.current(MOTEC) is not None and table.current(MOTEC).writer == ANNA  # type: ignore[union-attr]
    monkeypatch.setattr(node_lease, "LEASE_TTL_S", 0.0)  # her silence outlasts the lease
    assert table.current(MOTEC) is None
    runner.run(_write_as(BEN, session, REF, 10))  # the node is free: ben takes it
    monkeypatch.setattr(node_lease, "LEASE_TTL_S", 30.0)
    assert table.current(MOTEC).writer == BEN  # type: ignore[union-attr]
    assert not table.release(MOTEC, ANNA), "only the holder releases"
    assert table.release(MOTEC, BEN) and table.current(MOTEC) is None
    runner.run(_write_as(ANNA, session, REF, 15))
    broken = table.break_lease(MOTEC, "root (admin)")
    assert broken.writer == ANNA and table.current(MOTEC) is None
    runner.run(_write_as(BEN, session, REF, 11))


def test_an_operation_in_progress_keeps_the_lease(bench: tuple[asyncio.Runner, Session],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    runner, session = bench
    table = node_lease.leases(session)
    monkeypatch.setattr(node_lease, "LEASE_TTL_S", 0.0)

    async def scenario() -> None:
        with node_lease.writing(session, MOTEC, as_writer(ANNA)):  # e.g. a parameter-set download between two writes
            assert table.current(MOTEC) is not None, "held while the operation runs, whatever the TTL"
            with pytest.raises(NodeLeased, match="until the operation under way ends"):
                await _as(BEN, session, REF, 10)
        assert table.current(MOTEC) is None

    runner.run(scenario())


def test_stopping_is_never_refused(bench: tuple[asyncio.Runner, Session]) -> None:
    runner, session = bench
    runner.run(_write_as(ANNA, session, REF, 15))

    async def stop_as_ben() -> None:
        await parameters.write(session, MOTEC, REF, 15, ctx=as_writer(BEN).stopping(), verify=False)

    runner.run(stop_as_ben())  # no NodeLeased: any station may stop a machine
