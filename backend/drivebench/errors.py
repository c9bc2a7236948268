"""The error tree shared by every layer.

Each layer raises only its own branch; `web/problems.py` maps a class to an HTTP status once.
Lower layers convert foreign exceptions (python-can, canopen) with ``raise ... from exc``.
"""

from __future__ import annotations


class DriveBenchError(Exception):
    """Root of all errors the tool reports to a user."""

    title = "DriveBench error"

    def __init__(self, detail: str, *, hint: str | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.hint = hint

    def extra(self) -> dict[str, object]:
        """Fields added to the problem+json body next to ``detail``."""
        return {"hint": self.hint} if self.hint else {}


# --- transport -------------------------------------------------------------------------------------------
class TransportError(DriveBenchError):
    title = "CAN adapter error"


class AdapterUnavailable(TransportError):
    title = "CAN adapter not available"


class BusSpecError(TransportError):
    title = "Invalid bus specification"


# --- protocol --------------------------------------------------------------------------------------------
class ProtocolError(DriveBenchError):
    title = "CANopen protocol error"


class SdoAbortError(ProtocolError):
    title = "SDO transfer aborted"

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
    title = "No SDO response"

    def __init__(self, detail: str, *, node: int, index: int | None = None, subindex: int | None = None) -> None:
        super().__init__(detail, hint="Check that the node is powered, has this node id and the same bit rate, "
                                      "and that the bus is terminated at both ends.")
        self.node = node
        self.index = index
        self.subindex = subindex

    def extra(self) -> dict[str, object]:
        data: dict[str, object] = {**super().extra(), "node": self.node}
        if self.index is not None:
            data["object"] = f"0x{self.index:04X}sub{self.subindex or 0}"
        return data


class NodeOffline(ProtocolError):
    title = "Node offline"


# --- device ----------------------------------------------------------------------------------------------
class DeviceError(DriveBenchError):
    title = "Device profile error"


class ProfileError(DeviceError):
    """A profile file (EDS/JSON) cannot be loaded; ``source`` and ``line`` say where."""

    title = "Invalid device profile"

    def __init__(self, detail: str, *, source: str | None = None, line: int | None = None) -> None:
        where = f"{source}:{line}: " if source and line else (f"{source}: " if source else "")
        super().__init__(where + detail)
        self.source = source
        self.line = line

    def extra(self) -> dict[str, object]:
        return {**super().extra(), "source": self.source, "line": self.line}


class UnknownProfile(DeviceError):
    title = "Unknown device profile"


class ParameterError(DeviceError):
    title = "Parameter error"


class UnknownParameter(ParameterError):
    title = "Unknown parameter"


class OutOfRange(ParameterError):
    title = "Value out of range"


class InvalidValue(ParameterError):
    title = "Invalid value"


class ReadOnly(ParameterError):
    title = "Parameter is read-only"


# --- services --------------------------------------------------------------------------------------------
class ServiceError(DriveBenchError):
    title = "Request failed"


class NotFound(ServiceError):
    title = "Not found"


class Conflict(ServiceError):
    title = "Conflict"


class NotAuthenticated(ServiceError):
    title = "Not signed in"


class AccessDenied(ServiceError):
    title = "Not allowed"
