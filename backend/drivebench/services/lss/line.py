"""The LSS steps on a session's CAN bus: fastscan, assign a node ID (with bit rate and store) to one found device and
await its boot-up, switch state global, NMT reset communication to all (activate bit timing: :mod:`.bit_rate`).

One :class:`LssLine` per session holds the master and an asyncio lock: one LSS step at a time on a bus; the
blocking canopen calls run in a worker thread. Every configuring step is written to the audit log.
"""

from __future__ import annotations

import asyncio
import threading
import weakref
from dataclasses import dataclass, field

from drivebench.errors import DriveBenchError, InvalidValue, ProtocolError
from drivebench.i18n import N_, Text, _
from drivebench.protocol.canopen.lss import (
    BIT_TIMINGS,
    FastscanResult,
    LssAddress,
    LssError,
    LssMaster,
    LssNoAnswer,
    timing_index,
)
from drivebench.protocol.canopen.network import frames_of
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.services.bus.sessions import Session
from drivebench.services.control import drive_guard
from drivebench.services.lss import lss_audit
from drivebench.services.lss.guard_rule import admit_global
from drivebench.services.params.write_context import WriteContext

BOOT_WAIT_S = 5.0
SWITCH_GLOBAL_WAITING = "switch state global (waiting)"
RESET_OLD_ID = "NMT reset communication to it"
BITRATES = sorted(BIT_TIMINGS.values(), reverse=True)
MERGE_NOTE = N_("Identical LSS answers of several devices merge into one frame on the bus: a fastscan tells devices "
                "apart by their LSS address; two devices with the same address cannot be told apart by LSS (after "
                "addressing they answer on one node ID: the Plant page's duplicate check shows it).")


@dataclass
class Step:
    step: str
    ok: bool
    text: str


class LssStepFailed(ProtocolError):
    """A step of an LSS operation failed: the detail says which and why; ``steps`` what was done before."""

    title = N_("LSS step failed")

    def __init__(self, detail: str, steps: list[Step]) -> None:
        super().__init__(detail)
        self.steps = steps

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "steps": [step.__dict__ for step in self.steps]}


@dataclass
class LssLine:
    master: LssMaster
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    found: list[LssAddress] = field(default_factory=list)
    last_scan: FastscanResult | None = None
    assigned: dict[LssAddress, int] = field(default_factory=dict)


_lines: weakref.WeakKeyDictionary[Session, LssLine] = weakref.WeakKeyDictionary()


def line_of(session: Session) -> LssLine:
    line = _lines.get(session)
    if line is None:
        line = _lines[session] = LssLine(LssMaster(frames_of(session.network).canopen))
    return line


async def _audit(session: Session, ctx: WriteContext, node_id: int, step: str, value: str,
                 error: str | None = None) -> None:
    await lss_audit.record(session.id, ctx.user, node_id, step, value, error)


# --- fastscan -----------------------------------------------------------------------------------------------------
def fastscan_values(window_ms: float) -> dict[str, object]:
    return {"LSS": "fastscan", "answer window [ms]": window_ms, "then": SWITCH_GLOBAL_WAITING}


async def fastscan(session: Session, ctx: WriteContext, window_ms: float = 50) -> FastscanResult:
    """Every device without a node ID; each found one waits in configuration state until the switch state global
    (waiting) that ends the scan."""
    if not 2 <= window_ms <= 2000:
        raise InvalidValue(_("The answer window must be 2 ... 2000 ms."))
    await admit_global(session, _("LSS fastscan"), fastscan_values(window_ms), ctx)
    line = line_of(session)
    async with line.lock:
        line.master.window_s = window_ms / 1000
        try:
            result = await asyncio.to_thread(line.master.fastscan)
        finally:
            await asyncio.to_thread(line.master.switch_global, False)
        line.found, line.last_scan = result.found, result
    await _audit(session, ctx, 0, "fastscan", _("{count} devices found, {frames} frames, {seconds} s").format(
        count=len(result.found), frames=result.frames, seconds=f"{result.seconds:.2f}"))
    return result


# --- assign a node ID ---------------------------------------------------------------------------------------------
def assign_values(address: LssAddress, node_id: int, bitrate: int | None, store: bool) -> dict[str, object]:
    values: dict[str, object] = {"LSS": "assign", **address.hex(), "node ID": node_id}
    if bitrate is not None:
        values["bit rate"] = bitrate
    return {**values, "store": store, "then": SWITCH_GLOBAL_WAITING, "if it had a node ID": RESET_OLD_ID}


def _wait_for_boot(started: threading.Event) -> bool:
    return started.wait(BOOT_WAIT_S)


async def _select(master: LssMaster, address: LssAddress) -> None:
    """Switch state selective; when no device answers it but one answers the inquiry, a device never left LSS
    configuration state (a selective switch reaches only devices in waiting state): that is said."""
    try:
        await asyncio.to_thread(master.switch_selective, address)
    except LssNoAnswer as exc:
        if not await asyncio.to_thread(_still_configuring, master):
            raise
        raise LssError(Text(N_("no device answered switch state selective for serial {serial}, and a device is "
                               "still in LSS configuration state after switch state global (waiting): it does not "
                               "leave configuration state (LSS answers only there). Power-cycle the device that "
                               "does not start, then run the fastscan again."),
                            serial=f"0x{address.serial:08X}")) from exc


def _still_configuring(master: LssMaster) -> bool:
    """Does a device answer inquire node ID (only one in LSS configuration state does) after switch state global
    (waiting) went to all?"""
    try:
        master.inquire_node_id()
    except LssError:
        return False
    return True


async def assign(session: Session, ctx: WriteContext, address: LssAddress, node_id: int, *, bitrate: int | None,
                 store: bool) -> list[Step]:
    """Select the device by its address, configure the node ID (and bit timing), store, switch all to waiting:
    a device that had no node ID starts with the new one; its boot-up is awaited and the node added to the
    session. Each step's result in words; a failing step raises :class:`LssStepFailed` with the steps before."""
    if not 1 <= node_id <= 127:
        raise InvalidValue(_("the node ID must be 1 ... 127 (it was {node})").format(node=node_id))
    index = timing_index(bitrate) if bitrate is not None else None
    await admit_global(session, _("LSS addressing (ends with switch state global)"),
                       assign_values(address, node_id, bitrate, store), ctx)
    line = line_of(session)
    frames = frames_of(session.network)
    booted = threading.Event()

    def on_boot(can_id: int, data: bytearray, timestamp: float) -> None:
        if bytes(data[:1]) == b"\x00":
            booted.set()

    steps: list[Step] = []
    serial = f"0x{address.serial:08X}"
    async with line.lock:
        master = line.master
        selected = False
        frames.canopen.subscribe(0x700 + node_id, on_boot)
        try:
            await _select(master, address)
            selected = True
            had = await asyncio.to_thread(master.inquire_node_id)
            steps.append(Step("select", True, _("device with serial {serial} selected (its node ID: {had})").format(
                serial=serial, had=_("none") if had == 0xFF else had)))
            await asyncio.to_thread(master.configure_node_id, node_id)
            steps.append(Step("node_id", True, _("node ID {node} configured").format(node=node_id)))
            if index is not None and bitrate is not None:
                await asyncio.to_thread(master.configure_bit_timing, index)
                steps.append(Step("bit_timing", True, _("bit rate {rate} kbit/s configured (active after activate "
                                                        "bit timing or a power cycle)").format(rate=bitrate // 1000)))
            if store:
                await asyncio.to_thread(master.store_configuration)
                steps.append(Step("store", True, _("configuration stored in the device")))
            await asyncio.to_thread(master.switch_global, False)
            selected = False
            steps.append(Step("waiting", True, _("switch state global (waiting) sent")))
            if 1 <= had <= 127 and had != node_id:  # CiA 305: a configured device takes a new ID at reset comm.
                await asyncio.to_thread(frames.send_nmt, NmtCommand.RESET_COMMUNICATION, had)
                session.remove_node(had)
                steps.append(Step("reset", True, _("NMT reset communication sent to its old node ID {had}").format(
                    had=had)))
            if await asyncio.to_thread(_wait_for_boot, booted):
                steps.append(Step("boot", True, _("node {node} booted (boot-up telegram)").format(node=node_id)))
            elif await asyncio.to_thread(_still_configuring, master):
                steps.append(Step("boot", False, _(
                    "node {node} did not boot: the device with serial {serial} is still in LSS configuration state "
                    "after switch state global (waiting) - it still answers the LSS inquiry - so its new node ID "
                    "never became active. {next}").format(node=node_id, serial=serial, next=_(
                        "Power-cycle it: it starts with the node ID it stored.") if store else _(
                        "Assign again with Store and power-cycle it: it then starts with the stored node ID."))))
            else:
                steps.append(Step("boot", False, _("no boot-up of node {node} within {seconds} s: the device does "
                                                   "not start with its new node ID (is it still in LSS "
                                                   "configuration state?)").format(node=node_id,
                                                                                  seconds=f"{BOOT_WAIT_S:g}")))
        except DriveBenchError as exc:
            if selected:
                await asyncio.to_thread(master.switch_global, False)
            await _audit(session, ctx, node_id, "assign", f"{serial} -> {node_id}", str(exc.detail))
            raise LssStepFailed(exc.detail, steps) from exc
        finally:
            frames.canopen.unsubscribe(0x700 + node_id, on_boot)
        line.assigned[address] = node_id
        line.found = [found for found in line.found if found != address]
    await _audit(session, ctx, node_id, "assign", _("serial {serial} -> node ID {node}{rate}{store}").format(
        serial=serial, node=node_id, rate=f", {bitrate} bit/s" if bitrate else "", store=", stored" if store else ""))
    if steps[-1].ok:
        await session.identify(node_id)
        if node_id in session.nodes:
            steps.append(Step("session", True, _("node {node} added to the session ({device})").format(
                node=node_id, device=session.nodes[node_id].device_name)))
    return steps


# --- store the configuration of a device again ------------------------------------------------------------------
def store_values(address: LssAddress) -> dict[str, object]:
    return {"LSS": "store configuration", **address.hex(), "then": SWITCH_GLOBAL_WAITING}


async def store_configuration(session: Session, ctx: WriteContext, address: LssAddress) -> list[Step]:
    """Select the device by its address, store its node ID and bit timing (CiA 305 store configuration), switch all
    back to waiting. A device that keeps its node ID is not reset: it keeps running with it."""
    await admit_global(session, _("LSS store configuration (ends with switch state global)"), store_values(address),
                       ctx)
    line = line_of(session)
    serial = f"0x{address.serial:08X}"
    steps: list[Step] = []
    async with line.lock:
        master = line.master
        selected = False
        try:
            await asyncio.to_thread(master.switch_selective, address)
            selected = True
            had = await asyncio.to_thread(master.inquire_node_id)
            steps.append(Step("select", True, _("device with serial {serial} selected (its node ID: {had})").format(
                serial=serial, had=_("none") if had == 0xFF else had)))
            await asyncio.to_thread(master.store_configuration)
            steps.append(Step("store", True, _("configuration stored in the device")))
        except DriveBenchError as exc:
            await _audit(session, ctx, 0, "store configuration", serial, str(exc.detail))
            raise LssStepFailed(exc.detail, steps) from exc
        finally:
            if selected:
                await asyncio.to_thread(master.switch_global, False)
    await _audit(session, ctx, had if 1 <= had <= 127 else 0, "store configuration", serial)
    return steps


# --- the global steps ---------------------------------------------------------------------------------------------
async def switch_global(session: Session, ctx: WriteContext, configuration: bool) -> None:
    state = "configuration" if configuration else "waiting"
    await admit_global(session, _("LSS switch state global"), {"LSS": f"switch state global ({state})"}, ctx)
    line = line_of(session)
    async with line.lock:
        await asyncio.to_thread(line.master.switch_global, configuration)
    await _audit(session, ctx, 0, "switch state global", state)


async def reset_communication_all(session: Session, ctx: WriteContext) -> list[int]:
    """NMT reset communication to every node: a configured device takes a pending node ID with it."""
    await admit_global(session, _("NMT reset communication of all nodes"), {"NMT": "reset communication"}, ctx)
    targets = await drive_guard.nmt(session, NmtCommand.RESET_COMMUNICATION, 0, ctx.panel, ctx=ctx)
    await _audit(session, ctx, 0, "NMT reset communication", "all")
    return targets


async def identify_non_configured(session: Session) -> bool:
    line = line_of(session)
    async with line.lock:
        return await asyncio.to_thread(line.master.identify_non_configured)




# --- read-only inquiries ------------------------------------------------------------------------------------------
async def identify_remote(session: Session, vendor: int, product: int, revisions: tuple[int, int],
                          serials: tuple[int, int]) -> bool:
    """Is any device with this vendor and product, revision and serial in the ranges on the bus (one or many)?"""
    for low, high in (revisions, serials):
        if low > high:
            raise InvalidValue(_("a range's low end ({low}) is above its high end ({high})").format(low=low,
                                                                                                   high=high))
    line = line_of(session)
    async with line.lock:
        return await asyncio.to_thread(line.master.identify_remote, vendor, product, revisions, serials)


@dataclass(frozen=True)
class Inquiry:
    address: LssAddress
    node_id: int
    selected: bool
    """The device was switched to configuration state by this inquiry (it stays there until a switch state global
    (waiting))."""


async def inquire(session: Session, select: LssAddress | None) -> Inquiry:
    """Inquire vendor, product, revision, serial and node ID of the device in LSS configuration state; ``select``
    first switches that one device to configuration state (switch state selective: it reaches that device only and
    changes nothing it runs)."""
    line = line_of(session)
    async with line.lock:
        if select is not None:
            await asyncio.to_thread(line.master.switch_selective, select)
        address = await asyncio.to_thread(line.master.inquire_address)
        node_id = await asyncio.to_thread(line.master.inquire_node_id)
    return Inquiry(address, node_id, select is not None)
