"""Guided commissioning: the manuals' first-commissioning sequences, one step at a time, with the telegrams.

* MICROMASTER 4 (manual ch. 5.7 velocity mode, 5.8 profile torque mode): the SDO steps as printed, NMT start,
  shutdown / switch on / enable operation by RPDO1 (0x200 + node) and the first setpoint by RPDO5 (0x300 + node);
  the answer is the status word in TPDO1 (0x180 + node). The manual's BOP-only preconditions (P2051.4/5/6) are
  shown, not sent. The manual writes the BICO values with 0x22 (size not indicated); the SDO client sends 0x23.
* 8200 vector + EMF2178IB (ch. 6.5): CINH, C0001 = 3, controller enable by C0135, C0150 checked after each word.
* 93XX + EMF2178IB (ch. 6.5): C0005 = 1013, C0142 = 0, CINH set once, then enable by AIF word 1.
* 8400 motec: CAN1_IN word 1: SwitchOn, EnableOperation (bit names assumed, see ``drive_words``).

Each step records the frames of the node seen on the bus while it ran (both directions) and stops the run with
a message when the answer is not the expected one.
"""

from __future__ import annotations

import asyncio
import threading
import time
import uuid
from dataclasses import dataclass, field

import can
from pydantic import BaseModel

from drivebench.errors import Conflict, DriveBenchError, NotFound, SdoAbortError
from drivebench.protocol.nmt import NmtCommand
from drivebench.services import drive_control, parameters
from drivebench.services.drive_words import CIA402, EMF, EMF_AIF, L8400
from drivebench.services.sessions import Session, SessionNode

ANSWER_TIMEOUT_S = 3.0


@dataclass(frozen=True)
class Step:
    title: str
    kind: str  # "sdo" (write index/sub := data), "nmt_start", "pdo" (send cob offset + data), "check" (read ref)
    index: int = 0
    sub: int = 0
    data: bytes = b""
    cob: int = 0  # COB-ID base (0x200 RPDO1, 0x300 RPDO5), node id added
    expect_state: str | None = None
    expect_ref: str | None = None
    expect_value: int | None = None
    printed: str | None = None  # the request as the manual prints it
    moves: bool = False
    note: str | None = None


@dataclass(frozen=True)
class Sequence:
    key: str
    title: str
    source: str
    preconditions: tuple[str, ...]
    steps: tuple[Step, ...]


def _sdo(title: str, index: int, sub: int, value: int, size: int, printed_cmd: int | None = None,
         note: str | None = None, moves: bool = False) -> Step:
    data = value.to_bytes(size, "little")
    command = printed_cmd if printed_cmd is not None else {1: 0x2F, 2: 0x2B, 4: 0x23}[size]
    printed = bytes([command, index & 0xFF, index >> 8, sub]) + data.ljust(4, b"\0")
    return Step(title, "sdo", index, sub, data, printed=printed.hex(" "), note=note, moves=moves)


def _mm_mapping(index: int, second: int, second_name: str) -> list[Step]:
    first = 0x60400010 if index < 0x1800 else 0x60410010
    return [_sdo(f"0x{index:04X}.0 := 0 (mapping off)", index, 0, 0, 1),
            _sdo(f"0x{index:04X}.1 := 0x{first:08X}", index, 1, first, 4),
            _sdo(f"0x{index:04X}.2 := 0x{second:08X} ({second_name})", index, 2, second, 4),
            _sdo(f"0x{index:04X}.0 := 2", index, 0, 2, 1)]


def _mm_head(torque: bool) -> list[Step]:
    steps = [_sdo("P2040 = 0 (telegram off time)", 0x27F8, 0, 0, 2),
             _sdo("P0700 = 6 (command source CAN)", 0x22BC, 0, 6, 2),
             _sdo("P1000 = 6 (setpoint source CAN)", 0x23E8, 0, 6, 2),
             _sdo("P0719 = 0", 0x22CF, 0, 0, 2),
             _sdo("P1501 = r2091.12 (activates 0x6060)", 0x25DD, 0, 0x082B000C, 4, printed_cmd=0x22),
             _sdo("P1300 = 22 (sensorless vector control)" if torque else "P1300 = 0 (V/f operation)",
                  0x2514, 0, 22 if torque else 0, 2)]
    if torque:
        steps += [_sdo("P1503 = r2050.4 (activates 0x6071)", 0x25DF, 0, 0x08020004, 4, printed_cmd=0x22),
                  _sdo("0x6060 := 4 (profile torque mode)", 0x6060, 0, 4, 1),
                  Step("Check: 0x6061 = 4", "check", expect_ref="0x6061", expect_value=4, printed="40 61 60 00")]
    steps += [_sdo(f"0x{index:04X}.2 := 0xFF (transmission type)", index, 2, 0xFF, 1)
              for index in (0x1400, 0x1404, 0x1405, 0x1800, 0x1804, 0x1805)]
    return steps


def _mm_run(torque: bool) -> list[Step]:
    second = 0x60710010 if torque else 0x60420010
    actual = 0x60770010 if torque else 0x60440010
    first_run = (Step("Target torque 200 ‰ + CW 0x7F by RPDO5: the drive rotates", "pdo", cob=0x300,
                      data=bytes.fromhex("7f 00 c8 00"), expect_state="operation_enabled", moves=True)
                 if torque else
                 Step("Velocity 1000 rpm + CW 0x7F by RPDO5: the drive rotates", "pdo", cob=0x300,
                      data=bytes.fromhex("7f 00 e8 03"), expect_state="operation_enabled", moves=True))
    return [*_mm_mapping(0x1604, second, "target torque" if torque else "target velocity"),
            *_mm_mapping(0x1A04, actual, "actual torque" if torque else "vl control effort"),
            *_mm_mapping(0x1605, 0x60600008, "modes of operation"),
            *_mm_mapping(0x1A05, 0x60610008, "modes of operation display"),
            Step("NMT start node", "nmt_start", printed="000: 01 <node>"),
            Step("Shutdown (6) by RPDO1", "pdo", cob=0x200, data=bytes.fromhex("06 00"), expect_state="ready"),
            Step("Switch on (7) by RPDO1", "pdo", cob=0x200, data=bytes.fromhex("07 00"), expect_state="switched_on"),
            Step("Enable operation (F) by RPDO1", "pdo", cob=0x200, data=bytes.fromhex("0f 00"),
                 expect_state="operation_enabled", moves=True),
            first_run]


MM_PRE = ("On the BOP or start-up tool (not possible via CAN): P2051.6 = 55 (0x6061 active), "
          "P2051.5 = 63 (0x6044 active)",)
SEQUENCES = {
    "mm-velocity": Sequence("mm-velocity", "MICROMASTER first commissioning, velocity mode",
                            "MICROMASTER CANopen manual ch. 5.7", MM_PRE, (*_mm_head(False), *_mm_run(False))),
    "mm-torque": Sequence("mm-torque", "MICROMASTER 440 first commissioning, profile torque mode",
                          "MICROMASTER CANopen manual ch. 5.8",
                          ("Bit rate 500 kbit/s (0x27DA := 500, effective after restart)", *MM_PRE,
                           "P2051.4 = 80 (r0080 torque -> 0x6077)"), (*_mm_head(True), *_mm_run(True))),
    "emf-8200": Sequence("emf-8200", "8200 vector minimal enable (EMF2178IB)", "EMF2178IB manual ch. 6.5",
                         ("Terminal 28 (controller enable) HIGH", "QSP terminal (if assigned) HIGH"), (
        _sdo("C0135 := CINH (0x0200)", 0x5F78, 0, 0x0200, 2),
        _sdo("C0001 := 3 (process data via AIF; 3 x 10000)", 0x5FFE, 0, 30000, 4),
        Step("Check: C0150 device status = operation inhibited", "check", expect_ref="C0150",
             expect_state="operation_inhibited"),
        _sdo("C0135 := 0 (controller enable, QSP off)", 0x5F78, 0, 0x0000, 2, moves=True),
        Step("Check: C0150 device status = operation enabled", "check", expect_ref="C0150",
             expect_state="operation_enabled"),
        _sdo("C0135 := CINH again (back to operation inhibited)", 0x5F78, 0, 0x0200, 2),
        Step("Check: C0150 device status = operation inhibited", "check", expect_ref="C0150",
             expect_state="operation_inhibited"))),
    "emf-93xx": Sequence("emf-93xx", "93XX minimal enable (EMF2178IB)", "EMF2178IB manual ch. 6.5",
                         ("Terminal 28 HIGH", "Terminal E1 HIGH (QSP with C0005 = 1013)"), (
        _sdo("C0005 := 1013 (speed control via AIF; x 10000)", 0x5FFA, 0, 10130000, 4),
        _sdo("C0142 := 0 (protection against uncontrolled restart)", 0x5FFF - 142, 0, 0, 4),
        _sdo("AIF word 1 := CINH (0x0200)", 0x58E1, 1, 0x0200, 2),
        Step("Check: AIF-OUT word 1 = operation inhibited", "check", expect_ref="C1823/1",
             expect_state="operation_inhibited"),
        _sdo("AIF word 1 := 0 (controller enable)", 0x58E1, 1, 0x0000, 2, moves=True),
        Step("Check: AIF-OUT word 1 = operation enabled", "check", expect_ref="C1823/1",
             expect_state="operation_enabled"))),
    "l8400": Sequence("l8400", "8400 motec minimal enable (CAN1_IN word 1)", "8400 motec CANopen manual ch. 8.1",
                      ("Bit names of wCtrl assumed (LA_NCtrl); check against the 8400 reference manual",), (
        _sdo("C00866/1 := 0 (controller inhibited)", 0x5FFF - 866, 1, 0x0000, 2),
        Step("Check: CAN1_OUT word 1 = ready to switch on", "check", expect_ref="C00868/1", expect_state="ready"),
        _sdo("C00866/1 := 0x0001 (SwitchOn)", 0x5FFF - 866, 1, 0x0001, 2),
        Step("Check: switched on", "check", expect_ref="C00868/1", expect_state="switched_on"),
        _sdo("C00866/1 := 0x0009 (SwitchOn + EnableOperation)", 0x5FFF - 866, 1, 0x0009, 2, moves=True),
        Step("Check: operation enabled", "check", expect_ref="C00868/1", expect_state="operation_enabled"))),
}


def sequences_for(node: SessionNode) -> list[Sequence]:
    try:
        fam = drive_control.family(node)
    except DriveBenchError:
        return []
    if fam is CIA402:
        has_torque = node.catalog is not None and drive_control.has_ref(node.catalog, "0x6071")
        return [SEQUENCES["mm-velocity"], *([SEQUENCES["mm-torque"]] if has_torque else [])]
    if fam is EMF:
        return [SEQUENCES["emf-8200"]]
    if fam is EMF_AIF:
        return [SEQUENCES["emf-93xx"]]
    return [SEQUENCES["l8400"]] if fam is L8400 else []


# --- a run ---------------------------------------------------------------------------------------------------
class Telegram(BaseModel):
    direction: str  # "T" sent by the tool, "R" received
    cob_id: str
    data: str
    t: float


class StepResult(BaseModel):
    number: int
    title: str
    printed: str | None
    telegrams: list[Telegram]
    ok: bool
    message: str


class StepOut(BaseModel):
    number: int
    title: str
    printed: str | None
    moves: bool
    note: str | None


class RunOut(BaseModel):
    id: str
    node_id: int
    sequence: str
    title: str
    source: str
    preconditions: list[str]
    steps: list[StepOut]
    position: int
    results: list[StepResult]
    finished: bool
    failed: str | None


class _Capture(can.Listener):
    def __init__(self, node_id: int) -> None:
        self.node_id = node_id
        self.frames: list[can.Message] = []
        self._lock = threading.Lock()
        self.sent = {0x000, 0x600 + node_id, 0x200 + node_id, 0x300 + node_id, 0x400 + node_id, 0x500 + node_id}
        self.received = {0x580 + node_id, 0x180 + node_id, 0x280 + node_id, 0x380 + node_id, 0x480 + node_id}

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id in self.sent | self.received and not msg.is_error_frame:
            with self._lock:
                self.frames.append(msg)

    def take(self) -> list[can.Message]:
        with self._lock:
            frames, self.frames = self.frames, []
        return frames


@dataclass
class Run:
    id: str
    node_id: int
    sequence: Sequence
    position: int = 0
    results: list[StepResult] = field(default_factory=list)
    failed: str | None = None
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)

    @property
    def finished(self) -> bool:
        return self.failed is not None or self.position >= len(self.sequence.steps)

    def public(self) -> RunOut:
        seq = self.sequence
        return RunOut(id=self.id, node_id=self.node_id, sequence=seq.key, title=seq.title, source=seq.source,
                      preconditions=list(seq.preconditions),
                      steps=[StepOut(number=n + 1, title=s.title, printed=s.printed, moves=s.moves, note=s.note)
                             for n, s in enumerate(seq.steps)],
                      position=self.position, results=self.results, finished=self.finished, failed=self.failed)


class Wizard:
    def __init__(self) -> None:
        self.runs: dict[str, Run] = {}

    def start(self, session: Session, node: SessionNode, key: str) -> Run:
        sequence = next((seq for seq in sequences_for(node) if seq.key == key), None)
        if sequence is None:
            raise NotFound(f"No commissioning sequence '{key}' for {node.device_name}.")
        run = Run(uuid.uuid4().hex[:12], node.node_id, sequence)
        self.runs[run.id] = run
        return run

    def get(self, run_id: str) -> Run:
        if run_id not in self.runs:
            raise NotFound(f"Commissioning run {run_id} does not exist (any more).")
        return self.runs[run_id]


def wizard(session: Session) -> Wizard:
    return session.services.wizard


def _telegrams(capture: _Capture, t0: float) -> list[Telegram]:
    return [Telegram(direction="T" if msg.arbitration_id in capture.sent else "R",
                     cob_id=f"0x{msg.arbitration_id:03X}", data=bytes(msg.data).hex(" ").upper(),
                     t=round(max(0.0, msg.timestamp - t0), 4) if msg.timestamp > 1e6 else 0.0)
            for msg in capture.take()]


async def _state_of(session: Session, node: SessionNode, ref: str) -> tuple[str, int]:
    raw = (await parameters.read(session, node.node_id, ref)).raw
    word = int(raw) & 0xFFFF if isinstance(raw, int) else 0
    return drive_control.family(node).state_of(word), word


async def _send_and_wait_state(session: Session, node: SessionNode, cob_id: int, data: bytes, expected: str) -> str:
    """Send the RPDO, wait for TPDO1 with the expected state; without one (event TPDO unchanged) read the status
    word. The listener is attached before sending: the drive may answer before ``send`` returns."""
    fam = drive_control.family(node)
    loop = asyncio.get_running_loop()
    found: asyncio.Future[str] = loop.create_future()

    def settle(state: str) -> None:
        if not found.done():
            found.set_result(state)

    class Tpdo(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            if msg.arbitration_id == 0x180 + node.node_id and len(msg.data) >= 2:
                state = fam.state_of(int.from_bytes(msg.data[:2], "little"))
                if state == expected:
                    loop.call_soon_threadsafe(settle, state)

    tap = Tpdo()
    session.add_frame_listener(tap)
    try:
        await asyncio.to_thread(session.network.send, cob_id, data)
        return await asyncio.wait_for(found, ANSWER_TIMEOUT_S)
    except TimeoutError:
        state, word = await _state_of(session, node, fam.status_ref)
        return state if state == expected else f"{state} (status word 0x{word:04X})"
    finally:
        session.remove_frame_listener(tap)


async def _execute(session: Session, node: SessionNode, step: Step) -> str | None:
    """Run one step; the problem as text, or None when the answer is the expected one."""
    client = session.client(node.node_id)
    if step.kind == "sdo":
        try:
            await client.adownload(step.index, step.sub, step.data)
        except SdoAbortError as exc:
            return f"SDO abort 0x{exc.abort_code:08X} ({exc.abort_text}) instead of the download response 0x60."
        return None
    if step.kind == "nmt_start":
        await session.nmt(NmtCommand.START, node.node_id)
        await asyncio.sleep(0.05)
        return None
    if step.kind == "pdo":
        if step.expect_state is None:
            await asyncio.to_thread(session.network.send, step.cob + node.node_id, step.data)
            return None
        state = await _send_and_wait_state(session, node, step.cob + node.node_id, step.data, step.expect_state)
        return None if state == step.expect_state else \
            f"The drive answered '{state}', expected '{step.expect_state}'."
    assert step.expect_ref is not None
    if step.expect_state is not None:
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while True:
            state, word = await _state_of(session, node, step.expect_ref)
            if state == step.expect_state:
                return None
            if time.monotonic() > deadline:
                return (f"{step.expect_ref} = 0x{word:04X} shows '{state}', expected '{step.expect_state}'. Check "
                        "the preconditions (terminals, command source).")
            await asyncio.sleep(0.05)
    raw = (await parameters.read(session, node.node_id, step.expect_ref)).raw
    return None if raw == step.expect_value else f"{step.expect_ref} = {raw!r}, expected {step.expect_value}."


async def next_step(session: Session, node: SessionNode, run: Run, *, confirm: bool = False,
                    panel: drive_control.Panel = drive_control.SERVICE_PANEL) -> Run:
    """Run the next step; while another panel holds the armed drive, this panel cannot run steps."""
    async with run.lock:
        if run.finished:
            raise Conflict("This commissioning run is finished; start it again to repeat it.")
        step = run.sequence.steps[run.position]
        guard = drive_control.guard_for(session)
        guard.check(node.node_id, panel, f"Step {run.position + 1} ({step.title})")
        if step.moves:
            if not confirm:
                raise Conflict(f"Step {run.position + 1} ({step.title}) can make the motor turn: confirm it.")
            guard.arm(node.node_id, panel)
        capture = _Capture(node.node_id)
        session.add_frame_listener(capture)
        t0 = time.time()
        try:
            problem = await _execute(session, node, step)
        except DriveBenchError as exc:
            problem = str(exc)
        finally:
            await asyncio.sleep(0.02)  # let the last answer frame reach the capture
            session.remove_frame_listener(capture)
        run.results.append(StepResult(number=run.position + 1, title=step.title, printed=step.printed,
                                      telegrams=_telegrams(capture, t0), ok=problem is None,
                                      message=problem or "Answer as expected."))
        if problem is not None:
            run.failed = f"Stopped at step {run.position + 1} ({step.title}): {problem}"
        else:
            run.position += 1
        return run

