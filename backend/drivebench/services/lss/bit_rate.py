"""Activate bit timing (CiA 305) on a session's bus and follow it: after the switch delay the session's own adapter
is opened again at the new bit rate (python-can's ``bitrate=``, through the session's bus specification), then every
device the session knows is asked at the new rate - by identify remote slave for those known by their LSS address
(answered in either LSS state), by an SDO read of 0x1000 for the session's other nodes. A device that does not answer
is looked for once more at the old rate: there it was left behind; at neither rate it is silent. The answer names
which devices followed and which did not, with the next step."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field

from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _
from drivebench.protocol.canopen.lss import LssAddress, LssMaster, timing_index
from drivebench.protocol.canopen.network import frames_of
from drivebench.services.bus.sessions import Session
from drivebench.services.lss import lss_audit
from drivebench.services.lss.guard_rule import admit_global
from drivebench.services.lss.line import SWITCH_GLOBAL_WAITING, line_of
from drivebench.services.monitoring.monitor import monitor_for
from drivebench.services.params.write_context import WriteContext

CHECK_WAIT_S = 0.3
"""How long identify remote slave waits for a device (at the new rate, and at the old one)."""
SETTLE_S = 0.05
"""After twice the switch delay (CiA 305: devices switch after the first, and send after the second)."""
DEVICE_TYPE = 0x1000


CONFIGURATION_FIRST = "switch state global (configuration)"


def activate_values(bitrate: int, delay_ms: int, configuration_first: bool = False) -> dict[str, object]:
    values: dict[str, object] = {"LSS": "activate bit timing", "bit rate": bitrate, "switch delay [ms]": delay_ms}
    if configuration_first:
        values = {"before": CONFIGURATION_FIRST, **values, "then": SWITCH_GLOBAL_WAITING}
    return values


@dataclass(frozen=True)
class Behind:
    address: LssAddress
    at_old_rate: bool
    """It still answers at the old bit rate (it ignored the switch); False: at neither rate."""


@dataclass(frozen=True)
class BitRateSwitch:
    bitrate: int
    old_bitrate: int
    adapter_bitrate: int
    """The rate the session's adapter runs at afterwards."""
    checked: int
    followed: list[LssAddress]
    left_behind: list[Behind]
    nodes_followed: list[int] = field(default_factory=list)
    nodes_silent: list[int] = field(default_factory=list)
    """The session's nodes (not known by an LSS address) that do not answer an SDO read at the new rate."""
    text: str = ""


def _answering(master: LssMaster, known: list[LssAddress]) -> list[LssAddress]:
    """The devices among ``known`` that answer identify remote slave at the adapter's rate; those that did not are
    asked once more (a device may switch late, an answer come late on a busy machine)."""
    timeout, master.timeout_s = master.timeout_s, CHECK_WAIT_S
    try:
        answered = [address for address in known if _identify(master, address)]
        return [address for address in known if address in answered or _identify(master, address)]
    finally:
        master.timeout_s = timeout


def _identify(master: LssMaster, address: LssAddress) -> bool:
    return master.identify_remote(address.vendor, address.product, (address.revision, address.revision),
                                  (address.serial, address.serial))


def _node_answers(session: Session, node_id: int) -> bool:
    try:
        session.client(node_id).upload(DEVICE_TYPE, 0)
    except DriveBenchError:
        return False
    return True


def _serials(addresses: list[LssAddress]) -> str:
    return ", ".join(f"0x{address.serial:08X}" for address in addresses)


def _nodes(node_ids: list[int]) -> str:
    return ", ".join(str(node_id) for node_id in node_ids)


def _text(switch: BitRateSwitch) -> str:
    new, old = switch.bitrate // 1000, switch.old_bitrate // 1000
    parts = [_("This session's adapter now runs at {new} kbit/s.").format(new=new) if new != old else
             _("The bit rate stays {new} kbit/s.").format(new=new)]
    behind = [entry.address for entry in switch.left_behind if entry.at_old_rate]
    silent = [entry.address for entry in switch.left_behind if not entry.at_old_rate]
    if not switch.checked and not switch.nodes_followed and not switch.nodes_silent:
        parts.append(_("No device known by its LSS address to check: run a fastscan first."))
    elif switch.left_behind:
        parts.append(_("{count} of {known} devices did not follow to {new} kbit/s: serial {serials} does not answer "
                       "at {new} kbit/s.").format(count=len(switch.left_behind), known=switch.checked, new=new,
                                                 serials=_serials([entry.address for entry in switch.left_behind])))
    elif switch.checked:
        parts.append(_("All {known} known devices followed to {new} kbit/s: each answers at it.").format(
            known=switch.checked, new=new))
    if switch.followed and switch.left_behind:
        parts.append(_("Followed: serial {serials}.").format(serials=_serials(switch.followed)))
    if behind:
        parts.append(_("Serial {serials} still answers at {old} kbit/s: it did not switch (it ignored activate bit "
                       "timing, or was not configured to {new} kbit/s). Power-cycle it if it stored {new} kbit/s (it "
                       "starts at the rate it stored); else switch every device back to {old} kbit/s (configure bit "
                       "timing, activate it, the adapter follows) and repeat.").format(
            serials=_serials(behind), old=old, new=new))
    if silent:
        parts.append(_("Serial {serials} answers at neither {new} nor {old} kbit/s: is it powered and on this "
                       "bus? It may run at a third bit rate.").format(serials=_serials(silent), new=new, old=old))
    if switch.nodes_silent:
        parts.append(_("Node {nodes} does not answer at {new} kbit/s (SDO 0x1000): a device without LSS does not "
                       "switch; set its bit rate on the device itself.").format(nodes=_nodes(switch.nodes_silent),
                                                                               new=new))
    if switch.nodes_followed:
        parts.append(_("Node {nodes} answers at {new} kbit/s.").format(nodes=_nodes(switch.nodes_followed), new=new))
    return " ".join(parts)


async def activate_bit_timing(session: Session, ctx: WriteContext, bitrate: int, delay_ms: int, *,
                              configuration_first: bool = False) -> BitRateSwitch:
    """Every device in configuration state switches to the bit timing it was configured to after the delay; the
    session's adapter follows, and every known device is asked at the new rate (one that does not answer, once more
    at the old rate). ``configuration_first``: switch state global (configuration) before, and (waiting) at the
    new rate after."""
    timing_index(bitrate)
    if not 1 <= delay_ms <= 65535:
        raise InvalidValue(_("The switch delay must be 1 ... 65535 ms."))
    await admit_global(session, _("LSS activate bit timing"), activate_values(bitrate, delay_ms, configuration_first),
                       ctx)
    line = line_of(session)
    bus = frames_of(session.network).bus
    old = session.spec.bitrate
    known = list(dict.fromkeys([*line.found, *line.assigned]))
    by_lss = set(line.assigned.values())
    others = [node_id for node_id in sorted(session.nodes) if node_id not in by_lss]
    async with line.lock:
        if configuration_first:
            await asyncio.to_thread(line.master.switch_global, True)
        await asyncio.to_thread(line.master.activate_bit_timing, delay_ms)
        await lss_audit.record(session.id, ctx.user, 0, "activate bit timing", f"{bitrate} bit/s, {delay_ms} ms", None)
        await asyncio.sleep(2 * delay_ms / 1000 + SETTLE_S)
        if bitrate != old:
            await asyncio.to_thread(bus.reopen_at, bitrate)
            session.spec = bus.spec
        followed = await asyncio.to_thread(_answering, line.master, known)
        missing = [address for address in known if address not in followed]
        still_old: list[LssAddress] = []
        if missing and bitrate != old:  # a brief look at the old rate, then back
            await asyncio.to_thread(bus.reopen_at, old)
            try:
                still_old = await asyncio.to_thread(_answering, line.master, missing)
            finally:
                await asyncio.to_thread(bus.reopen_at, bitrate)
        if configuration_first:
            await asyncio.to_thread(line.master.switch_global, False)
        answers = [await asyncio.to_thread(_node_answers, session, node_id) for node_id in others]
    monitor_for(session).follow_bitrate(bus.spec.bitrate)
    switch = BitRateSwitch(bitrate, old, bus.spec.bitrate, len(known), followed,
                           [Behind(address, address in still_old) for address in missing],
                           [node for node, ok in zip(others, answers, strict=True) if ok],
                           [node for node, ok in zip(others, answers, strict=True) if not ok])
    return BitRateSwitch(**{**switch.__dict__, "text": _text(switch)})
