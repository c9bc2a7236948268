"""The parameter service's public names in one place, for code that still imports them from here: the service
lives in modules by job (:mod:`~drivebench.services.params.lookup` naming and search,
:mod:`~drivebench.services.params.reads`, :mod:`~drivebench.services.params.writes` with
:mod:`~drivebench.services.params.write_ports`, :mod:`~drivebench.services.params.device_commands`,
:mod:`~drivebench.services.params.sdo2`, :mod:`~drivebench.services.params.read_all`, the session's part in
:mod:`~drivebench.services.params.session_part`); new code imports those."""

from drivebench.services.params.device_commands import CommandResult, DeviceCommand, command
from drivebench.services.params.lookup import groups, items, parameter_sets, readable_items, resolve
from drivebench.services.params.read_all import read_node, silence_watch, start_read
from drivebench.services.params.reads import MAX_BATCH, display, read, read_many, snapshot
from drivebench.services.params.sdo2 import sdo_channels
from drivebench.services.params.session_part import (
    ParametersPart,
    SdoSettings,
    SessionParameters,
    attach,
    configure,
    service,
    stop_first,
)
from drivebench.services.params.values import ParameterValue, WriteResult
from drivebench.services.params.write_ports import MovingWrites, WriteAttempt, WriteAudit, WriteAudits
from drivebench.services.params.writes import (
    checked_raw,
    encoded,
    given_value,
    send_logged,
    sent_key,
    sent_value,
    sent_values,
    write,
)

__all__ = [
    "MAX_BATCH",
    "CommandResult",
    "DeviceCommand",
    "MovingWrites",
    "ParameterValue",
    "ParametersPart",
    "SdoSettings",
    "SessionParameters",
    "WriteAttempt",
    "WriteAudit",
    "WriteAudits",
    "WriteResult",
    "attach",
    "checked_raw",
    "command",
    "configure",
    "display",
    "encoded",
    "given_value",
    "groups",
    "items",
    "parameter_sets",
    "read",
    "read_many",
    "read_node",
    "readable_items",
    "resolve",
    "sdo_channels",
    "send_logged",
    "sent_key",
    "sent_value",
    "sent_values",
    "service",
    "silence_watch",
    "snapshot",
    "start_read",
    "stop_first",
    "write",
]
