"""This server process among the DriveBench servers that share one database, and whether another one has ended."""

from __future__ import annotations

import os
import socket

SERVER = f"{socket.gethostname()}:{os.getpid()}"
"""This server process: host and process id, as rows it holds (downloads, wizard steps) name their holder."""


def ended(server: str) -> bool:
    """Whether ``server`` (host:pid) is a process of this machine that has ended; another machine's cannot be looked
    up, so it is not taken for ended (its lease or its own end tells)."""
    host, _sep, pid = server.rpartition(":")
    if host != socket.gethostname() or not pid.isdigit():
        return False
    try:
        os.kill(int(pid), 0)  # signal 0: only asks whether the process exists
    except ProcessLookupError:
        return True
    except PermissionError:  # it exists, run by another user
        return False
    return False
