"""What is wrong with a file given as ``--tls-cert`` / ``--tls-key``, in words, before OpenSSL says "PEM lib"."""

from __future__ import annotations

import os
import pwd
from pathlib import Path

from drivebench.errors import InvalidValue
from drivebench.i18n import N_, _

_CERTIFICATE = b"-----BEGIN CERTIFICATE-----"
_PRIVATE_KEY = b"PRIVATE KEY-----"
_ENCRYPTED = b"-----BEGIN ENCRYPTED PRIVATE KEY-----"
_MAKE_ONE = N_("`drivebench tls self-signed --host NAME` makes a certificate and key for a plant network.")


def _user() -> str:
    uid = os.geteuid()
    try:
        return f"{pwd.getpwuid(uid).pw_name} (uid {uid})"
    except KeyError:
        return f"uid {uid}"


def read_pem(option: str, path: Path) -> bytes:
    """The file's bytes, or :class:`InvalidValue` saying why it cannot be read and what to do."""
    if path.is_dir():
        raise InvalidValue(_("{option} {path} is a folder, not a file: give the PEM file inside it.").format(
            option=option, path=path))
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise InvalidValue(_("{option} {path}: no such file. {make_one}").format(
            option=option, path=path, make_one=_(_MAKE_ONE))) from None
    except PermissionError:
        raise InvalidValue(_("{option} {path}: the server runs as {user}, who may not read this file. Let that user "
                             "read it (chown or chmod), or start the server as a user who may.").format(
            option=option, path=path, user=_user())) from None
    except OSError as exc:
        raise InvalidValue(_("{option} {path} cannot be read: {reason}.").format(
            option=option, path=path, reason=exc.strerror)) from None


def check_pem(option: str, path: Path, content: bytes) -> None:
    """A certificate where a certificate belongs and an unencrypted private key where a key belongs."""
    has_cert, has_key = _CERTIFICATE in content, _PRIVATE_KEY in content
    if option == "--tls-cert" and not has_cert:
        if has_key:
            raise InvalidValue(_("--tls-cert {path} holds a private key, not a certificate: were --tls-cert and "
                                 "--tls-key swapped?").format(path=path))
        raise InvalidValue(_("--tls-cert {path} is not a PEM certificate (no line -----BEGIN CERTIFICATE-----): "
                             "give the certificate file (.crt or .pem). {make_one}").format(
            path=path, make_one=_(_MAKE_ONE)))
    if option == "--tls-key" and not has_key:
        if has_cert:
            raise InvalidValue(_("--tls-key {path} holds a certificate, not a private key: give the key file "
                                 "made with the certificate.").format(path=path))
        raise InvalidValue(_("--tls-key {path} is not a PEM private key (no line -----BEGIN … PRIVATE KEY-----): "
                             "give the key file made with the certificate. {make_one}").format(
            path=path, make_one=_(_MAKE_ONE)))
    if option == "--tls-key" and _ENCRYPTED in content:
        raise InvalidValue(_("--tls-key {path} is encrypted with a passphrase, which the server cannot ask for: "
                             "give an unencrypted key (openssl pkey -in {path} -out NEW.key), readable by the "
                             "server's user only.").format(path=path))
