"""The :class:`WriteContext` a test that calls a service directly writes with (a web request builds its own,
``web/safety.write_context``)."""

from __future__ import annotations

from drivebench.services.params.write_context import LOCAL_USER, SERVICE_PANEL, WriteContext, Writer

SERVICE = WriteContext.internal(user=LOCAL_USER, origin="parameters")
"""A service's own writes without a request: no lease taken (refused while someone holds the node), nothing
confirmed (a moving value is refused with 428 unless the call confirms it)."""


def as_writer(writer: Writer | None) -> WriteContext:
    """Writes of ``writer`` (the node lease's holder), as a request of that writer carries them."""
    return WriteContext.request(user=LOCAL_USER, origin="parameters", panel=SERVICE_PANEL, writer=writer,
                                confirmation=None)
