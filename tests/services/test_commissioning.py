"""Guided commissioning replayed against the simulated demo plant: the MICROMASTER velocity and torque sequences
(manual ch. 5.7 / 5.8) and the EMF2178IB minimal enable, with the telegrams each step saw on the bus."""

from __future__ import annotations

import asyncio

import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.errors import ConfirmationRequired, Conflict, InvalidValue
from drivebench.services.bus.sessions import Session
from drivebench.services.control import commissioning
from drivebench.services.control.commissioning import Run
from drivebench.services.params import parameters
from drivebench.services.session_manager import SessionManager
from drivebench.simulator.plant import Plant, PlantFile
from tests.confirming import confirmed_call
from tests.conftest import fresh_channel
from tests.write_contexts import SERVICE

MM, VECTOR = 3, 12


@pytest.fixture
def bench(plant_session: tuple[asyncio.Runner, Session]) -> tuple[asyncio.Runner, Session]:
    return plant_session


def _walk(runner: asyncio.Runner, session: Session, run: Run, stop_before: int | None = None,
          values: dict[str, object] | None = None) -> Run:
    """Run the steps; ``values`` gives a ``parameter`` step's value by its ref (else the profile's proposal)."""
    node = session.node(run.node_id)
    while not run.finished and run.position != stop_before:
        step = run.sequence.steps[run.position]
        value = (values or {}).get(step.ref or "")
        runner.run(confirmed_call(commissioning.next_step, session, node, run, confirm=run.node_id, value=value,
                                  ctx=SERVICE) if step.moves
                   else commissioning.next_step(session, node, run, value=value, ctx=SERVICE))
        commissioning.drive_control.guard_for(session).keepalive(run.node_id)
    return run


def test_offered_sequences_per_device(bench: tuple[asyncio.Runner, Session]) -> None:
    _, session = bench
    assert [seq.key for seq in commissioning.sequences_for(session.node(MM))] == ["mm-velocity", "mm-torque",
                                                                                  "mm-quick"]
    assert [seq.key for seq in commissioning.sequences_for(session.node(VECTOR))] == ["emf-8200"]
    assert [seq.key for seq in commissioning.sequences_for(session.node(5))] == ["l8400"]


def test_every_sdo_step_of_the_seed_sequences_is_a_write_the_profile_admits(
        bench: tuple[asyncio.Runner, Session]) -> None:
    """Each SDO step is the checked write of a profile item's value (issue 30 item 2): in range, and sending it
    puts the step's own bytes on the wire (the data type's width, nothing truncated)."""
    _, session = bench
    checked = 0
    for node_id in (MM, 5, VECTOR):
        node = session.node(node_id)
        for sequence in commissioning.sequences_for(node):
            for step in sequence.steps:
                if step.kind != "sdo":
                    continue
                write = commissioning.step_write(node, step)
                item, raw = parameters.checked_raw(node, write.ref, write.value)
                assert (item.index, item.subindex) == (step.index, step.sub), (sequence.key, step.title)
                assert parameters.encoded(item, raw, write.value) == step.data, (sequence.key, step.title, raw)
                checked += 1
    assert checked > 50  # the MICROMASTER's telegram sequences; the Lenze ones are parameter steps


def test_lenze_sequences_are_parameter_steps_on_the_profiles_parameters(
        bench: tuple[asyncio.Runner, Session]) -> None:
    """Issue 30 item 3: the 8200 vector and 8400 motec sequences name their profiles' parameters (no fixed bytes),
    each shown as a form field, and say in the profile which of the manual's steps the profile cannot offer."""
    _, session = bench
    for node_id in (5, VECTOR):
        node = session.node(node_id)
        (sequence,) = commissioning.sequences_for(node)
        assert {step.kind for step in sequence.steps} == {"parameter", "check"}, sequence.key
        for step in sequence.steps:
            if step.kind == "parameter":
                assert commissioning.field_of(node, step) is not None, (sequence.key, step.ref)
        assert sequence.missing, sequence.key


def test_micromaster_velocity_sequence_as_printed(bench: tuple[asyncio.Runner, Session]) -> None:
    runner, session = bench
    wizard = commissioning.wizard(session)
    run = _walk(runner, session, wizard.start(session, session.node(MM), "mm-velocity", SERVICE))
    assert run.failed is None and all(result.ok for result in run.results), run.failed
    first = run.results[0]
    assert first.printed == "2b f8 27 00 00 00 00 00"
    assert [(t.direction, t.cob_id, t.data) for t in first.telegrams] == [
        ("T", "0x603", "2B F8 27 00 00 00 00 00"), ("R", "0x583", "60 F8 27 00 00 00 00 00")]
    switch_on = next(result for result in run.results if result.title.startswith("Switch on"))
    assert ("T", "0x203", "07 00") in [(t.direction, t.cob_id, t.data) for t in switch_on.telegrams]
    assert any(t.cob_id == "0x183" and t.data == "33 FE" for t in switch_on.telegrams)  # as printed
    assert run.results[-1].telegrams[0].data == "7F 00 E8 03"


def test_moving_step_needs_confirmation(bench: tuple[asyncio.Runner, Session]) -> None:
    runner, session = bench
    run = commissioning.wizard(session).start(session, session.node(VECTOR), "emf-8200", SERVICE)
    moving = next(n for n, step in enumerate(run.sequence.steps) if step.moves)
    _walk(runner, session, run, stop_before=moving)
    with pytest.raises(ConfirmationRequired, match="confirm"):
        runner.run(commissioning.next_step(session, session.node(VECTOR), run, ctx=SERVICE))
    with pytest.raises(ConfirmationRequired, match="confirm"):  # a bare true does not name the node
        runner.run(commissioning.next_step(session, session.node(VECTOR), run, confirm=True, ctx=SERVICE))
    _walk(runner, session, run)
    assert run.failed is None and run.finished
    assert any(t.cob_id == "0x58C" for t in run.results[2].telegrams)  # the C0150 read's answer


def test_unexpected_answer_stops_the_run_with_a_message(bench: tuple[asyncio.Runner, Session],
                                                         plant: Plant) -> None:
    runner, session = bench
    run = commissioning.wizard(session).start(session, session.node(MM), "mm-velocity", SERVICE)
    shutdown = next(n for n, step in enumerate(run.sequence.steps) if step.title.startswith("Shutdown"))
    _walk(runner, session, run, stop_before=shutdown)
    drive = plant.nodes[MM].drive
    assert drive is not None
    drive.raise_fault(7)
    _walk(runner, session, run)
    assert run.failed is not None and "Shutdown" in run.failed and "expected 'ready'" in run.failed
    assert run.position == shutdown and not run.results[-1].ok
    with pytest.raises(Conflict):
        runner.run(commissioning.next_step(session, session.node(MM), run, ctx=SERVICE))


def test_micromaster_torque_sequence_as_printed(bench: tuple[asyncio.Runner, Session]) -> None:
    runner, session = bench
    run = _walk(runner, session, commissioning.wizard(session).start(session, session.node(MM), "mm-torque", SERVICE))
    assert run.failed is None, run.failed
    check = next(result for result in run.results if result.title == "Check: 0x6061 = 4")
    assert [t.data[:14] for t in check.telegrams] == ["40 61 60 00 00", "4F 61 60 00 04"]
    bico = next(result for result in run.results if result.title.startswith("P1503"))
    assert bico.printed == "22 df 25 00 04 00 02 08"  # as printed; the client sends it with the size (0x23)
    assert bico.telegrams[0].data == "23 DF 25 00 04 00 02 08"


def test_8400_minimal_enable(bench: tuple[asyncio.Runner, Session]) -> None:
    runner, session = bench
    run = _walk(runner, session, commissioning.wizard(session).start(session, session.node(5), "l8400", SERVICE),
                values={"C00088": 4.2})
    assert run.failed is None, run.failed
    assert all(result.ok for result in run.results), [result.message for result in run.results]
    current = next(result for result in run.results if result.title.startswith("C00088"))
    assert [(t.direction, t.data) for t in current.telegrams][:3] == [  # 4.2 A x 100 = 420, then read back
        ("T", "23 A7 5F 00 A4 01 00 00"), ("R", "60 A7 5F 00 00 00 00 00"), ("T", "40 A7 5F 00 00 00 00 00")]
    assert runner.run(parameters.read(session, 5, "C00088")).value == 4.2
    moving = [step.ref for step in run.sequence.steps if step.moves]
    assert moving[-1] == "C00866/1"  # the enable step stays a confirmed moving step


def test_93xx_minimal_enable(registry: ProfileRegistry) -> None:
    """C0005 = 1013, C0142 = 0: the controller enables only after CINH was set once (EMF2178IB ch. 6.5); the
    panel names the AIF word 1 bits as the manual's 93XX tables do (column C0005 = 1xx3)."""
    plant_file = PlantFile.model_validate({"name": "93XX", "bus": "virtual:x@500000", "nodes": [
        {"node_id": 7, "profile": "lenze-93xx-emf2178ib"}]})
    plant = Plant(plant_file, registry.get, bus=f"virtual:{fresh_channel()}@500000", latency="0ms").start()
    runner = asyncio.Runner()
    manager = SessionManager(registry, sdo_timeout_s=1.0, sdo_retries=1)
    try:
        session = runner.run(manager.open(plant.spec, "93xx"))
        node = session.add_node(7, "lenze-93xx-emf2178ib")
        assert [seq.key for seq in commissioning.sequences_for(node)] == ["emf-93xx"]
        run = _walk(runner, session, commissioning.wizard(session).start(session, node, "emf-93xx", SERVICE))
        assert run.failed is None, run.failed
        status = runner.run(commissioning.drive_control.read_status(session, node))
        assert status.family == "emf2178ib-aif" and status.control_ref == "C1822/1"
        named = {bit.bit: (bit.name, bit.set) for bit in status.status_bits}  # the 93XX table, not the 8200 one
        assert named[13] == ("DCTRL-MESS", False) and named[3] == ("MCTRL-MMAX", False)
        assert named[15] == ("Ready for operation (DCTRL-RDY)", True)
        assert status.control_bits[2].name == "NSET-N-INV"
    finally:
        runner.run(manager.close_all())
        runner.close()
        plant.stop()


def test_the_generic_cia402_set_up_writes_the_servos_standard_objects(bench: tuple[asyncio.Runner, Session]) -> None:
    """Issue 30 item 3: node 7 (a CiA 402 drive with no commissioning section) is offered the set-up built from
    the standard objects its profile lists; each step is the checked write, read back, of the user's value or the
    profile's default, and the objects the profile lacks are named."""
    runner, session = bench
    servo = session.node(7)
    (setup,) = commissioning.sequences_for(servo)
    assert setup.key == "cia402-setup"
    refs = [step.ref for step in setup.steps]
    assert refs[:3] == ["0x6060", "0x607D.1", "0x607D.2"] and "0x6092.1" in refs and refs[-1] == "0x609A"
    assert "0x6080" in setup.missing[0] and "0x6080" not in refs  # the servo's profile has no max motor speed
    run = _walk(runner, session, commissioning.wizard(session).start(session, servo, "cia402-setup", SERVICE),
                values={"0x6083": 5000, "0x607D.2": 7200})
    assert run.failed is None and all(result.ok for result in run.results), run.failed
    assert runner.run(parameters.read(session, 7, "0x6083")).raw == 5000
    assert runner.run(parameters.read(session, 7, "0x607D.2")).raw == 7200
    accel = next(result for result in run.results if result.title.startswith("0x6083"))
    assert [t.data[:11] for t in accel.telegrams] == ["23 83 60 00", "60 83 60 00", "40 83 60 00", "43 83 60 00"]
    assert [seq.key for seq in commissioning.sequences_for(session.node(MM))][-1] == "mm-quick"  # 0x6060 alone


def test_a_set_up_value_outside_the_range_is_refused_and_the_step_stays(bench: tuple[asyncio.Runner, Session]) -> None:
    runner, session = bench
    servo = session.node(7)
    run = commissioning.wizard(session).start(session, servo, "cia402-setup", SERVICE)
    _walk(runner, session, run, stop_before=1)
    before = runner.run(parameters.read(session, 7, "0x607D.1")).raw
    with pytest.raises(InvalidValue):
        runner.run(commissioning.next_step(session, servo, run, value="far left", ctx=SERVICE))
    assert run.position == 1 and runner.run(parameters.read(session, 7, "0x607D.1")).raw == before
