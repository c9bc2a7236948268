"""A drive's faults in the manual's words: the present fault and the history, from what the EMCY consumer already
holds (no bus traffic), and why a command did nothing: the drive is in fault (its state machine says so; the present
fault named), or the profile names the parameter that routes commands elsewhere than the fieldbus (its
``faults.command_source``: one read)."""

from __future__ import annotations

from pydantic import BaseModel

from drivebench.device.drive.faults import DecodedFault, decode_number
from drivebench.errors import DriveBenchError
from drivebench.i18n import _
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.monitoring.diagnostics import EmcyRecord, emcy_history, emcy_record
from drivebench.services.params import reads


def present_fault(session: Session, node: SessionNode) -> EmcyRecord | None:
    """The emergency still active on the node (None: none, or the last one was the error-free 0x0000)."""
    active = session.network.emcy.active(node.node_id)
    return emcy_record(active, node.profile) if active else None


def fault_history(session: Session, node_id: int) -> list[EmcyRecord]:
    """The node's emergencies that reported an error (not the error-free 0x0000), newest first, with their times."""
    return [record for record in emcy_history(session, node_id) if not record.is_reset]


def fault_words(record: EmcyRecord | None) -> str:
    """The present fault in a few words: the device's own number with the manual's text, else the EMCY code's."""
    if record is None:
        return _("no emergency telegram names it")
    fault = record.fault
    if fault is None:
        return f"EMCY {record.code}: {record.text}"
    if fault.text:
        return f"{fault.label}: {fault.text}"
    return f"{fault.label}, EMCY {record.code}: {record.text}"


def refusal_note(state_label: str, present: EmcyRecord | None, reset: str | None) -> str:
    """Why a command to enable did nothing: the drive is in a fault state of its state machine (``state_label``);
    ``reset`` names the command that acknowledges the fault (None: the control has none)."""
    if reset is None:
        return _("{state}: the drive does not enable while a fault is present ({fault}).").format(
            state=state_label, fault=fault_words(present))
    return _("{state}: the drive does not enable while a fault is present ({fault}). Remove its cause, then send "
             "“{reset}”.").format(state=state_label, fault=fault_words(present), reset=reset)


async def command_source_note(session: Session, node: SessionNode) -> str | None:
    """Words for a drive that takes its commands from elsewhere than the fieldbus (``P0700 = 2: commands come from
    Terminal; set P0700 = 6 for the fieldbus``); None when the fieldbus commands it or the profile does not say."""
    section = node.profile.faults if node.profile else None
    routing = section.command_source if section else None
    if routing is None:
        return None
    try:
        value = await reads.read(session, node.node_id, routing.ref)
    except DriveBenchError as exc:
        return _("{ref} could not be read ({error}): whether commands reach the drive over the fieldbus is "
                 "unknown.").format(ref=routing.ref, error=exc)
    raw = value.raw
    if not isinstance(raw, int) or raw in routing.fieldbus:
        return None
    wanted = " / ".join(str(v) for v in routing.fieldbus)
    if value.text:
        return _("{ref} = {value} ({source}): the drive takes its commands from there, not from the fieldbus; set "
                 "{ref} = {wanted} for the fieldbus.").format(ref=routing.ref, value=raw, source=value.text,
                                                                wanted=wanted)
    return _("{ref} = {value}: the drive takes its commands from elsewhere, not from the fieldbus; set {ref} = "
             "{wanted} for the fieldbus.").format(ref=routing.ref, value=raw, wanted=wanted)


class FaultParameter(BaseModel):
    """A present-fault or fault-history parameter of the profile's ``faults`` section, as read now."""

    ref: str
    name: str | None = None
    display: str | None = None
    fault: DecodedFault | None = None
    """The number read, in the manual's words (None: 0 = no fault, or not read)."""
    error: str | None = None
    """Why it could not be read."""


class Faults(BaseModel):
    node_id: int
    present: EmcyRecord | None
    """The emergency still active (from the EMCY consumer)."""
    history: list[EmcyRecord]
    """The emergencies that reported an error, newest first, with their times."""
    parameters: list[FaultParameter]
    """The profile's present-fault and fault-history parameters, read from the device."""
    command_note: str | None
    not_covered: str | None
    """What the profile's sources did not give."""


async def read_fault_parameters(session: Session, node: SessionNode) -> list[FaultParameter]:
    section = node.profile.faults if node.profile else None
    if section is None:
        return []
    found = []
    for ref in section.present + section.history:
        try:
            value = await reads.read(session, node.node_id, ref)
        except DriveBenchError as exc:
            found.append(FaultParameter(ref=ref, error=str(exc)))
            continue
        raw = value.raw
        fault = decode_number(section, raw) if isinstance(raw, int) and raw else None
        found.append(FaultParameter(ref=value.ref, name=value.name, display=value.display, fault=fault))
    return found


async def faults(session: Session, node: SessionNode) -> Faults:
    """Everything the Diagnostics tab and the API say about the node's faults (reads the profile's fault
    parameters and its command source: a few SDO reads)."""
    section = node.profile.faults if node.profile else None
    return Faults(node_id=node.node_id, present=present_fault(session, node),
                  history=fault_history(session, node.node_id),
                  parameters=await read_fault_parameters(session, node),
                  command_note=await command_source_note(session, node),
                  not_covered=section.not_covered if section else None)
