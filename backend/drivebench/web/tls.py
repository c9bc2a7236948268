"""HTTPS for a plant network: a self-signed certificate for the server's names, a check that a certificate and key
belong together (said in words before uvicorn starts), and HSTS when asked for.

Certificates are made with ``cryptography``; uvicorn serves them (``ssl_certfile`` / ``ssl_keyfile``)."""

from __future__ import annotations

import datetime as dt
import ipaddress
import ssl
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from drivebench.errors import InvalidValue
from drivebench.i18n import _
from drivebench.web.tls_files import check_pem, read_pem

if TYPE_CHECKING:
    from cryptography import x509

HSTS_HEADER = (b"strict-transport-security", b"max-age=31536000")
"""One year, without includeSubDomains: a plant server's name says nothing about its neighbours."""


@dataclass(frozen=True)
class Certificate:
    cert_pem: bytes
    key_pem: bytes
    sha256: str
    """Fingerprint as browsers show it (AA:BB:…), so a user can compare it before trusting the certificate."""


def _subject_names(hosts: list[str]) -> list[x509.GeneralName]:
    from cryptography import x509

    names: list[x509.GeneralName] = []
    for host in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host.strip("[]"))))
        except ValueError:
            names.append(x509.DNSName(host))
    return names


def self_signed(hosts: list[str], days: int = 825) -> Certificate:
    """A certificate for ``hosts`` (names and addresses), valid for ``days`` (825: what browsers still accept)."""
    if not hosts:
        raise InvalidValue(_("A certificate needs at least one host name or address (--host)."))
    if not 1 <= days <= 3650:
        raise InvalidValue(_("--days {days}: a certificate is made for 1 to 3650 days.").format(days=days))
    # Imported here, for `drivebench tls` only: cryptography's X.509 modules are ~0.05 s of every server start.
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, hosts[0]),
                      x509.NameAttribute(NameOID.ORGANIZATION_NAME, "DriveBench (self-signed)")])
    now = dt.datetime.now(dt.UTC)
    cert = (x509.CertificateBuilder()
            .subject_name(name).issuer_name(name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5))
            .not_valid_after(now + dt.timedelta(days=days))
            .add_extension(x509.SubjectAlternativeName(_subject_names(hosts)), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
            .sign(key, hashes.SHA256()))
    digest = cert.fingerprint(hashes.SHA256()).hex().upper()
    return Certificate(
        cert_pem=cert.public_bytes(serialization.Encoding.PEM),
        key_pem=key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                  serialization.NoEncryption()),
        sha256=":".join(digest[i:i + 2] for i in range(0, len(digest), 2)))


def write_pair(certificate: Certificate, folder: Path, stem: str = "drivebench") -> tuple[Path, Path]:
    """``stem.crt`` and ``stem.key`` (readable by its owner only) in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    cert_file, key_file = folder / f"{stem}.crt", folder / f"{stem}.key"
    key_file.touch(mode=0o600, exist_ok=True)
    key_file.chmod(0o600)
    key_file.write_bytes(certificate.key_pem)
    cert_file.write_bytes(certificate.cert_pem)
    return cert_file, key_file


def check_pair(cert_file: Path | None, key_file: Path | None) -> None:
    """Both given, both readable, the certificate a certificate, the key a key and the certificate's: else
    :class:`InvalidValue` in words (which file, what is wrong, what to do)."""
    if (cert_file is None) != (key_file is None):
        given, missing = ("--tls-cert", "--tls-key") if key_file is None else ("--tls-key", "--tls-cert")
        raise InvalidValue(_("{given} needs {missing} too: HTTPS takes a certificate and its private key.").format(
            given=given, missing=missing))
    if cert_file is None or key_file is None:
        return
    for option, path in (("--tls-cert", cert_file), ("--tls-key", key_file)):
        check_pem(option, path, read_pem(option, path))
    try:
        ssl.create_default_context(ssl.Purpose.CLIENT_AUTH).load_cert_chain(cert_file, key_file)
    except ssl.SSLError as exc:
        reason = _("the key does not belong to the certificate") if "KEY_VALUES_MISMATCH" in str(exc) else str(exc)
        raise InvalidValue(_("--tls-cert {cert} with --tls-key {key}: {reason}.").format(
            cert=cert_file, key=key_file, reason=reason)) from exc
    except (OSError, ValueError) as exc:
        raise InvalidValue(_("--tls-cert {cert} / --tls-key {key} cannot be read as PEM: {reason}.").format(
            cert=cert_file, key=key_file, reason=exc)) from exc
