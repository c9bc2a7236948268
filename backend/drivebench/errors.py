"""The error tree shared by every layer.

Each layer raises only its own branch; `web/problems.py` maps a class to an HTTP status once.
Lower layers convert foreign exceptions (python-can, canopen) with ``raise ... from exc``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Self

from drivebench.i18n import N_, Text, _, shown


class DriveBenchError(Exception):
    """Root of all errors the tool reports to a user."""

    title = N_("DriveBench error")
    _template: str | None = None  # see keep_template
    _values: Mapping[str, object] = {}

    def __init__(self, detail: str, *, hint: str | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.hint = hint

    def extra(self) -> dict[str, object]:
        """Fields added to the problem+json body next to ``detail``."""
        return {"hint": self.hint} if self.hint else {}

    def shown_detail(self) -> str:
        """``detail`` in the language of whoever reads it (web/problems.py calls it in the request's language); an
        error raised outside a request (a bus thread) keeps an N_() template and its values for this."""
        return _(self._template).format(**self._values) if self._template else shown(self.detail)

    def keep_template(self, template: str, **values: object) -> Self:
        """Keeps the N_() text ``detail`` was formatted from (``detail`` itself stays the English text)."""
        self._template, self._values = template, values
        return self


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


class SdoAbortError(ProtocolError):
    title = N_("SDO transfer aborted")

    def __init__(self, abort_code: int, abort_text: str, *, node: int, index: int, subindex: int,
                 detail: str | None = None) -> None:
        super().__init__(detail or f"Node {node}: 0x{index:04X}sub{subindex}: "
                                   f"SDO abort 0x{abort_code:08X} {abort_text}")
        self.abort_code = abort_code
        self.abort_text = abort_text
        self.node = node
        self.index = index
        self.subindex = subindex

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "abort_code": f"0x{self.abort_code:08X}", "abort_text": self.abort_text,
                "node": self.node, "object": f"0x{self.index:04X}sub{self.subindex}"}


class SdoTimeoutError(ProtocolError):
    title = N_("No SDO response")
    NO_ANSWER = N_("Node {node} did not answer the SDO request for {object} ({reason})")

    def __init__(self, detail: str, *, node: int, index: int | None = None, subindex: int | None = None) -> None:
        super().__init__(detail, hint=N_("Check that the node is powered, has this node id and the same bit rate, "
                                         "and that the bus is terminated at both ends."))
        self.node = node
        self.index = index
        self.subindex = subindex

    def extra(self) -> dict[str, object]:
        data: dict[str, object] = {**super().extra(), "node": self.node}
        if self.index is not None:
            data["object"] = f"0x{self.index:04X}sub{self.subindex or 0}"
        return data


class SdoStalledError(SdoTimeoutError):
    """The node answered the start of a segmented (or block) transfer, then stopped answering."""

    title = N_("Node stopped answering")

    def __init__(self, *, node: int, index: int, subindex: int, done: int, total: int | None,
                 what: str | None = None, kind: str = "segmented") -> None:
        what = what or f"0x{index:04X}sub{subindex}"
        of_total = f" of {total}" if total is not None else ""
        super().__init__(f"Node {node} stopped answering during a {kind} transfer of {what} after {done}{of_total} "
                         f"segments", node=node, index=index, subindex=subindex)
        self.hint = ("The node answered the start of the transfer, so it is on the bus: it may have reset or "
                     "be overloaded. The transfer was aborted; read again once it answers.")
        self.done, self.total, self.what, self.kind = done, total, what, kind

    def named(self, what: str) -> SdoStalledError:
        return SdoStalledError(node=self.node, index=self.index or 0, subindex=self.subindex or 0, done=self.done,
                               total=self.total, what=what, kind=self.kind)

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "segments_done": self.done, "segments_total": self.total}


class SdoOutOfStepError(ProtocolError):
    """The node answered, but not what the transfer expects: the wrong toggle bit, another object, another
    command. ``answered`` is the (index, subindex) the answer named when it named the wrong object."""

    title = N_("SDO answer out of step")

    def __init__(self, reason: str, *, node: int, index: int, subindex: int,
                 answered: tuple[int, int] | None = None, what: str | None = None) -> None:
        asked = f"0x{index:04X} sub {subindex}"
        label = f" ({what})" if what and what != asked else ""
        if reason == "toggle":
            text = (f"Node {node}: toggle bit error: the node answered out of step during the segmented "
                    f"transfer of {asked}{label}")
        elif reason == "object" and answered is not None:
            text = f"Node {node}: answer for 0x{answered[0]:04X} sub {answered[1]} while {asked}{label} was asked"
        else:
            text = f"Node {node}: unexpected SDO answer for {asked}{label}: {reason}"
        super().__init__(text, hint="Another SDO client on the same channel (a second master or a tool) or a "
                                    "device fault can cause this; the transfer was aborted.")
        self.reason, self.node, self.index, self.subindex = reason, node, index, subindex
        self.answered, self.what = answered, what

    def named(self, what: str) -> SdoOutOfStepError:
        return SdoOutOfStepError(self.reason, node=self.node, index=self.index, subindex=self.subindex,
                                 answered=self.answered, what=what)

    def extra(self) -> dict[str, object]:
        data: dict[str, object] = {**super().extra(), "node": self.node,
                                   "object": f"0x{self.index:04X}sub{self.subindex}"}
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
    """An action that can move a drive was sent without the explicit confirmation naming its node (HTTP 428)."""

    title = N_("Confirmation required")


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
