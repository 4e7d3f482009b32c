"""The X.509 side of fleet credentials (`gmmap.fleet.security.credentials` describes the layout):
the files and their modes, PEM parsing with typed errors, and `verify_member`, the check of a
peer's certificate against the fleet's CA and CRL. All crypto is the `cryptography` package's.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

from cryptography import x509
from cryptography.exceptions import InvalidSignature, UnsupportedAlgorithm
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
from cryptography.x509.oid import NameOID

from gmmap import names
from gmmap.errors import (
    CredentialsError,
    CredentialsFileError,
    InsecureKeyError,
    RevokedMemberError,
    UntrustedMemberError,
)
from gmmap.names import NAME_RE

ROLES = ("robot", "station")
# A UUID-derived OID (ITU-T X.667, arc 2.25): ours without registering a private enterprise
# number. Non-critical, so TLS stacks that do not know it (rustls) still accept the certificate.
SIGNING_KEY_OID = x509.ObjectIdentifier("2.25.100706341961693446153537327100633527693")
SKEW = timedelta(minutes=5)  # certificates start a little early: robots' clocks differ

CA_KEY, CA_CERT, CRL, ISSUED = "ca.key", "ca.pem", "crl.pem", "issued"
KEY, TLS_KEY_FILE, CERT = "key.pem", "tls.key", "cert.pem"
MEMBER_JSON, PEERS = "member.json", "peers"


def utcnow() -> datetime:
    return datetime.now(timezone.utc)


def read_file(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise CredentialsFileError(f"{path}: missing") from None
    except OSError as err:
        raise CredentialsFileError(f"{path}: {err.strerror}") from None


def write_new(path: Path, data: bytes, mode: int) -> None:
    # Created with its final mode and O_EXCL: a key is never readable by others, not even
    # between open and chmod, and nothing existing is overwritten by accident.
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.chmod(path, mode)  # exactly `mode`, whatever the umask


def replace_file(path: Path, data: bytes, mode: int = 0o644) -> None:
    """Atomically: a robot reading the CRL meanwhile sees the old one or the new one."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.unlink(missing_ok=True)
    write_new(tmp, data, mode)
    os.replace(tmp, path)


def check_private(path: Path) -> None:
    try:
        mode = path.stat().st_mode & 0o777
    except FileNotFoundError:
        raise CredentialsFileError(f"{path}: missing") from None
    if os.name == "posix" and mode & 0o077:
        raise InsecureKeyError(
            f"{path}: permissions {mode:04o} let others read this private key; chmod 600 {path}"
        )


def load_private_key(path: Path) -> Any:
    check_private(path)
    try:
        return serialization.load_pem_private_key(read_file(path), password=None)
    except (ValueError, TypeError, UnsupportedAlgorithm):
        raise CredentialsFileError(
            f"{path}: not an unencrypted PEM private key (truncated or corrupt?)"
        ) from None


def private_pem(key: Any) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )


def cert_pem(cert: x509.Certificate) -> bytes:
    return cert.public_bytes(serialization.Encoding.PEM)


def load_cert(path: Path) -> x509.Certificate:
    try:
        return x509.load_pem_x509_certificate(read_file(path))
    except ValueError:
        raise CredentialsFileError(
            f"{path}: not a PEM certificate (truncated or corrupt?)"
        ) from None


def load_crl(path: Path) -> x509.CertificateRevocationList:
    try:
        return x509.load_pem_x509_crl(read_file(path))
    except ValueError:
        raise CredentialsFileError(f"{path}: not a PEM CRL (truncated or corrupt?)") from None


def spki(public_key: Any) -> bytes:
    return public_key.public_bytes(
        serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    )


def check_name(what: str, name: object) -> str:
    return names.check_name(what, name, CredentialsError)


def attribute(name: x509.Name, oid: x509.ObjectIdentifier) -> str | None:
    values = name.get_attributes_for_oid(oid)
    return str(values[0].value) if len(values) == 1 else None


@dataclass(frozen=True)
class Member:
    """A peer whose certificate the fleet's authority issued, valid and not revoked."""

    fleet: str
    name: str
    role: str
    public_key: Ed25519PublicKey = field(repr=False)  # the signing key (SIGNING_KEY_OID)
    serial: int
    not_after: datetime
    certificate: x509.Certificate = field(repr=False, compare=False)

    def verify(self, message: bytes, signature: bytes) -> bool:
        """Whether ``signature`` is this member's Ed25519 signature of ``message``."""
        try:
            self.public_key.verify(signature, message)
        except (InvalidSignature, ValueError, TypeError):
            return False
        return True


def check_authority(
    ca: x509.Certificate, crl: x509.CertificateRevocationList, fleet: str, now: datetime
) -> None:
    if attribute(ca.subject, NameOID.COMMON_NAME) != fleet:
        raise UntrustedMemberError(f"the CA certificate is not fleet {fleet!r}'s authority")
    if not ca.not_valid_before_utc <= now <= ca.not_valid_after_utc:
        raise UntrustedMemberError(
            f"fleet {fleet!r}'s CA certificate is not valid now (until {ca.not_valid_after_utc:%F})"
        )
    if crl.issuer != ca.subject or not crl.is_signature_valid(ca.public_key()):
        raise CredentialsFileError(f"the CRL was not signed by fleet {fleet!r}'s authority")
    if crl.next_update_utc is None or now > crl.next_update_utc:
        raise UntrustedMemberError(
            f"fleet {fleet!r}'s CRL is stale (next update was {crl.next_update_utc}): "
            "gmmap fleet refresh DIR, then copy crl.pem to the members"
        )


def _peer_cert(cert_pem: bytes | x509.Certificate) -> x509.Certificate:
    if isinstance(cert_pem, x509.Certificate):
        return cert_pem
    try:
        return x509.load_pem_x509_certificate(bytes(cert_pem))
    except (ValueError, TypeError):
        raise UntrustedMemberError("not a PEM certificate (truncated or garbage)") from None


def _signing_key(cert: x509.Certificate, who: str) -> Ed25519PublicKey:
    try:
        value = cert.extensions.get_extension_for_oid(SIGNING_KEY_OID).value
        key = serialization.load_der_public_key(value.value)  # type: ignore[attr-defined]
    except (x509.ExtensionNotFound, ValueError, UnsupportedAlgorithm):
        key = None
    if not isinstance(key, Ed25519PublicKey):
        raise UntrustedMemberError(f"certificate of {who!r} carries no Ed25519 signing key")
    return key


def member_of(cert: x509.Certificate, fleet: str) -> Member:
    name = attribute(cert.subject, NameOID.COMMON_NAME)
    role = attribute(cert.subject, NameOID.ORGANIZATIONAL_UNIT_NAME)
    if name is None or not NAME_RE.fullmatch(name) or role not in ROLES:
        raise UntrustedMemberError(f"{cert.subject.rfc4514_string()!r} is no member certificate")
    try:
        is_ca = cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    except x509.ExtensionNotFound:
        is_ca = True
    if is_ca:
        raise UntrustedMemberError(f"certificate of {name!r} is not a member certificate (CA)")
    return Member(
        fleet, name, role, _signing_key(cert, name), cert.serial_number,
        cert.not_valid_after_utc, cert,
    )  # fmt: skip


def verify_member(
    cert_pem: bytes | x509.Certificate,
    ca: x509.Certificate,
    crl: x509.CertificateRevocationList,
    fleet: str,
    *,
    now: datetime | None = None,
) -> Member:
    """The member a peer's certificate names, if ``ca`` (fleet ``fleet``'s authority) issued
    it, it is valid now and ``crl`` does not revoke it; `UntrustedMemberError` (or
    `RevokedMemberError`) otherwise."""
    now = now or utcnow()
    cert = _peer_cert(cert_pem)
    check_authority(ca, crl, fleet, now)
    who = attribute(cert.subject, NameOID.COMMON_NAME) or cert.subject.rfc4514_string()
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        raise UntrustedMemberError(
            f"certificate of {who!r} was not issued by fleet {fleet!r}'s authority"
        ) from None
    if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
        raise UntrustedMemberError(
            f"certificate of {who!r} is valid {cert.not_valid_before_utc:%F} to "
            f"{cert.not_valid_after_utc:%F}, not now"
        )
    if crl.get_revoked_certificate_by_serial_number(cert.serial_number) is not None:
        raise RevokedMemberError(f"{who!r} has been revoked from fleet {fleet!r}")
    return member_of(cert, fleet)
