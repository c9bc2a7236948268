"""The error tree shared by every layer.

Each layer raises only its own branch; `web/problems.py` maps a class to an HTTP status once.
Lower layers convert foreign exceptions (python-can, canopen) with ``raise ... from exc``.
"""

from __future__ import annotations

import threading
from collections import Counter

from drivebench.i18n import N_, Text, _, shown

SDO_FAILURES: Counter[str] = Counter()
"""SDO timeouts and aborts since the process started, by kind ("timeout", "abort"), counted where every SDO failure
of every transport becomes an error of this tree (the metrics endpoint reads it)."""
_failures_lock = threading.Lock()


def _count_sdo_failure(kind: str) -> None:
    with _failures_lock:
        SDO_FAILURES[kind] += 1


class DriveBenchError(Exception):
    """Root of all errors the tool reports to a user."""

    title = N_("DriveBench error")

    def __init__(self, detail: str, *, hint: str | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.hint = hint

    def extra(self) -> dict[str, object]:
        """Fields added to the problem+json body next to ``detail``."""
        return {"hint": self.hint} if self.hint else {}

    def shown_detail(self) -> str:
        """``detail`` in the language of whoever reads it (web/problems.py calls it in the request's language); an
        error raised outside a request (a bus thread) gives its detail as a :class:`~drivebench.i18n.Text` for this."""
        return shown(self.detail)

    def shown_hint(self) -> str | None:
        """``hint`` in the reader's language: a :class:`~drivebench.i18n.Text` put into words now, a plain one
        marked N_() translated."""
        if not self.hint:
            return None
        return shown(self.hint) if isinstance(self.hint, Text) else _(self.hint)


# --- transport -------------------------------------------------------------------------------------------
class TransportError(DriveBenchError):
    title = N_("CAN adapter error")


class AdapterUnavailable(TransportError):
    title = N_("CAN adapter not available")


class BusSpecError(TransportError):
    title = N_("Invalid bus specification")


# --- protocol --------------------------------------------------------------------------------------------
class ProtocolError(DriveBenchError):
    title = N_("CANopen protocol error")


def _object(index: int, subindex: int) -> str:
    return f"0x{index:04X}sub{subindex}"


class SdoAbortError(ProtocolError):
    """``abort_text`` is CiA 301's text (a :class:`~drivebench.i18n.Text`, protocol/abort_codes.py: German where
    shown) or the device manual's (as it prints it); ``shown_abort_text()`` is the reader's."""

    title = N_("SDO transfer aborted")
    DETAIL = N_("Node {node}: {object}: SDO abort {code} {text}")

    def __init__(self, abort_code: int, abort_text: str, *, node: int, index: int, subindex: int,
                 detail: str | None = None) -> None:
        super().__init__(detail or Text(self.DETAIL, node=node, object=_object(index, subindex),
                                        code=f"0x{abort_code:08X}", text=abort_text))
        self.abort_code = abort_code
        self.abort_text = abort_text
        self.node = node
        self.index = index
        self.subindex = subindex
        _count_sdo_failure("abort")

    def shown_abort_text(self) -> str:
        return shown(self.abort_text)

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "abort_code": f"0x{self.abort_code:08X}", "abort_text": self.shown_abort_text(),
                "node": self.node, "object": _object(self.index, self.subindex)}


class SdoTimeoutError(ProtocolError):
    title = N_("No SDO response")
    NO_ANSWER = N_("Node {node} did not answer the SDO request for {object} ({reason})")
    HINT = N_("Check that the node is powered, has this node id and the same bit rate, and that the bus is "
              "terminated at both ends.")

    def __init__(self, detail: str, *, node: int, index: int | None = None, subindex: int | None = None,
                 hint: str | None = HINT) -> None:
        super().__init__(detail, hint=hint)
        self.node = node
        self.index = index
        self.subindex = subindex
        _count_sdo_failure("timeout")

    def extra(self) -> dict[str, object]:
        data: dict[str, object] = {**super().extra(), "node": self.node}
        if self.index is not None:
            data["object"] = _object(self.index, self.subindex or 0)
        return data


class SdoStalledError(SdoTimeoutError):
    """The node answered the start of a segmented transfer (or of a fragmented SDO information response), then
    stopped answering. ``what`` names the object when a caller knows better than its index."""

    title = N_("Node stopped answering")
    STALLED = N_("Node {node} stopped answering {during} of {what} after {done} segments")
    STALLED_OF = N_("Node {node} stopped answering {during} of {what} after {done} of {total} segments")
    DURING = {"segmented": N_("during a segmented transfer"), "fragmented": N_("during a fragmented transfer")}
    STALLED_HINT = N_("The node answered the start of the transfer, so it is on the bus: it may have reset or be "
                      "overloaded. The transfer was aborted; read again once it answers.")

    def __init__(self, *, node: int, index: int, subindex: int, done: int, total: int | None,
                 what: str | None = None, kind: str = "segmented") -> None:
        what = what or _object(index, subindex)
        template = self.STALLED_OF if total is not None else self.STALLED
        super().__init__(Text(template, node=node, during=Text(self.DURING[kind]), what=what, done=done, total=total),
                         node=node, index=index, subindex=subindex, hint=self.STALLED_HINT)
        self.done, self.total, self.what, self.kind = done, total, what, kind

    def named(self, what: str) -> SdoStalledError:
        return SdoStalledError(node=self.node, index=self.index or 0, subindex=self.subindex or 0, done=self.done,
                               total=self.total, what=what, kind=self.kind)

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "segments_done": self.done, "segments_total": self.total}


class WriteOutcomeUnknown(SdoTimeoutError):
    """A download the node never confirmed: it may have written the value (its answer lost) or not. ``read_back``
    is what the node holds after it, read once (None: that read failed too or the object is write-only)."""

    title = N_("Outcome of the write unknown")
    HELD = N_("Node {node} did not confirm the write of {value} to {ref}: the outcome is unknown. Read back "
              "afterwards, the node holds {held}.")
    UNREAD = N_("Node {node} did not confirm the write of {value} to {ref}: the outcome is unknown, and {ref} could "
                "not be read back ({why}).")
    WRITE_ONLY = N_("Node {node} did not confirm the write of {value} to {ref}: the outcome is unknown, and {ref} is "
                    "write-only, so it cannot be read back.")
    UNKNOWN_HINT = N_("The node may have written the value and its answer been lost. Check the value before "
                      "writing again.")

    def __init__(self, detail: str, *, node: int, index: int, subindex: int, read_back: str | None) -> None:
        super().__init__(detail, node=node, index=index, subindex=subindex, hint=self.UNKNOWN_HINT)
        self.read_back = read_back

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "outcome": "unknown", "read_back": self.read_back}


class SdoOutOfStepError(ProtocolError):
    """The node answered, but not what the transfer expects: the wrong toggle bit (``TOGGLE``), another object
    (``OTHER_OBJECT``, ``answered`` the (index, subindex) the answer named), or anything else (``reason``, a
    :class:`~drivebench.i18n.Text`)."""

    title = N_("SDO answer out of step")
    TOGGLE, OTHER_OBJECT = "toggle", "object"
    TOGGLE_TEXT = N_("Node {node}: toggle bit error: the node answered out of step during the segmented transfer "
                     "of {asked}{label}")
    OTHER_OBJECT_TEXT = N_("Node {node}: answer for {answered} while {asked}{label} was asked")
    UNEXPECTED_TEXT = N_("Node {node}: unexpected SDO answer for {asked}{label}: {reason}")
    HINT = N_("Another SDO client on the same channel (a second master or a tool) or a device fault can cause "
              "this; the transfer was aborted.")

    def __init__(self, reason: str, *, node: int, index: int, subindex: int,
                 answered: tuple[int, int] | None = None, what: str | None = None) -> None:
        asked = f"0x{index:04X} sub {subindex}"
        label = f" ({what})" if what and what != asked else ""
        values: dict[str, object] = {"node": node, "asked": asked, "label": label}
        if reason == self.TOGGLE:
            text = Text(self.TOGGLE_TEXT, **values)
        elif reason == self.OTHER_OBJECT and answered is not None:
            text = Text(self.OTHER_OBJECT_TEXT, answered=f"0x{answered[0]:04X} sub {answered[1]}", **values)
        else:
            text = Text(self.UNEXPECTED_TEXT, reason=reason, **values)
        super().__init__(text, hint=self.HINT)
        self.reason, self.node, self.index, self.subindex = reason, node, index, subindex
        self.answered, self.what = answered, what

    def named(self, what: str) -> SdoOutOfStepError:
        return SdoOutOfStepError(self.reason, node=self.node, index=self.index, subindex=self.subindex,
                                 answered=self.answered, what=what)

    def extra(self) -> dict[str, object]:
        data: dict[str, object] = {**super().extra(), "node": self.node,
                                   "object": _object(self.index, self.subindex)}
        if self.answered is not None:
            data["answered_object"] = f"0x{self.answered[0]:04X}sub{self.answered[1]}"
        return data


class NodeOffline(ProtocolError):
    title = N_("Node offline")


# --- device ----------------------------------------------------------------------------------------------
class DeviceError(DriveBenchError):
    title = N_("Device profile error")


class ProfileError(DeviceError):
    """A profile file (EDS/JSON) cannot be loaded; ``source`` and ``line`` say where, ``reason`` what (a
    :class:`~drivebench.i18n.Text` when it may be shown later, in another language: a file read at start)."""

    title = N_("Invalid device profile")

    def __init__(self, detail: str, *, source: str | None = None, line: int | None = None) -> None:
        where = f"{source}:{line}: " if source and line else (f"{source}: " if source else "")
        super().__init__(Text.joined("", [where, detail]))
        self.reason = detail
        self.source = source
        self.line = line

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "source": self.source, "line": self.line}


class UnknownProfile(DeviceError):
    title = N_("Unknown device profile")


class ParameterError(DeviceError):
    title = N_("Parameter error")


class UnknownParameter(ParameterError):
    title = N_("Unknown parameter")


class OutOfRange(ParameterError):
    title = N_("Value out of range")


class InvalidValue(ParameterError):
    title = N_("Invalid value")


class ReadOnly(ParameterError):
    title = N_("Parameter is read-only")


# --- services --------------------------------------------------------------------------------------------
class ServiceError(DriveBenchError):
    title = N_("Request failed")


class NotFound(ServiceError):
    title = N_("Not found")


class Conflict(ServiceError):
    title = N_("Conflict")


class ConfirmationRequired(ServiceError):
    """An action that can move a drive was sent without the explicit confirmation naming its node (HTTP 428). The
    problem names what a confirmation must repeat: ``confirm_node`` (a node id, or ``all``) and ``confirm_values``."""

    title = N_("Confirmation required")

    def __init__(self, detail: str, *, node: int | str, values: dict[str, object] | None = None,
                 hint: str | None = None) -> None:
        super().__init__(detail, hint=hint)
        self.node = node
        self.values = values

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "confirm_node": self.node, "confirm_values": self.values}


class ContentTooLarge(ServiceError):
    """A request body past the upload limit, refused before it is read (HTTP 413)."""

    title = N_("Upload too large")


class NotAuthenticated(ServiceError):
    title = N_("Not signed in")


class AccessDenied(ServiceError):
    title = N_("Not allowed")


class UnknownHostName(ServiceError):
    """A request addressed (``Host``) to a name that is not this server's: DNS rebinding, refused with 400."""

    title = N_("Not this server's name")


class DatabaseUnavailable(ServiceError):
    """The database (``DRIVEBENCH_DATABASE_URL``) cannot be reached: which host, what failed, what to check (503)."""

    title = N_("Database unreachable")


class SchemaTooNew(ServiceError):
    """The database was upgraded by a newer release: this one does not know its schema and leaves it alone (503)."""

    title = N_("Database schema newer than this release")
