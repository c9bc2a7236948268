"""The key that signs the session cookies, kept in a file: made atomically (a reader never sees it half written),
mode 0600, and an empty file refused in words rather than used as an empty signing key."""

from __future__ import annotations

import contextlib
import os
import secrets
import tempfile
from pathlib import Path

from drivebench.errors import ServiceError
from drivebench.i18n import _


def _refuse_empty(path: Path) -> ServiceError:
    return ServiceError(_("The secret key file {path} is empty: an empty key would let anyone sign a session "
                          "cookie. Delete the file (DriveBench makes a new key; everyone signs in again) or write "
                          "the key shared by your servers into it (DRIVEBENCH_SECRET_KEY_FILE).").format(path=path))


def _read(path: Path) -> str:
    key = path.read_text().strip()
    if not key:
        raise _refuse_empty(path)
    return key


def _write_new(path: Path) -> None:
    """A new key in a temporary file of the same folder (0600, fsynced), linked to ``path`` only if no other
    process made it first: the name appears with the whole key behind it, and a key already there is kept."""
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(descriptor, "w") as file:  # mkstemp makes it 0600
            file.write(secrets.token_urlsafe(48) + "\n")
            file.flush()
            os.fsync(file.fileno())
        with contextlib.suppress(FileExistsError):  # another process made it first: its key is the key
            os.link(temporary, path)
        folder = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(folder)
        finally:
            os.close(folder)
    finally:
        os.unlink(temporary)


def kept_key(path: Path) -> str:
    """The key in ``path``, made there first when there is none."""
    with contextlib.suppress(FileNotFoundError):
        return _read_or_say(path)
    try:
        _write_new(path)
    except OSError as exc:
        raise ServiceError(_("Cannot make the secret key file {path}: {reason}. Let the server's user write that "
                             "folder, or give the key with DRIVEBENCH_SECRET_KEY_FILE / DRIVEBENCH_SECRET_KEY.").format(
            path=path, reason=exc.strerror)) from None
    return _read_or_say(path)


def _read_or_say(path: Path) -> str:
    try:
        return _read(path)
    except FileNotFoundError:
        raise
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else _("it is not UTF-8 text")
        raise ServiceError(_("Cannot read the secret key file {path}: {reason}.").format(
            path=path, reason=reason)) from None
