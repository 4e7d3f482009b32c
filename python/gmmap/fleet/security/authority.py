"""The fleet authority (``gmmap fleet init`` / ``add`` / ``revoke`` / ``show``): a CA in a
folder that issues member keys and certificates and signs the revocation list. The layout and
the certificate profile are in `gmmap.fleet.security.credentials`.

TLS_KEY switches the TLS key type: "ed25519" (the CA's key and each member's TLS key are
Ed25519; a member's signing key is its TLS key) or "p256" (ECDSA P-256 with SHA-256, should
rustls refuse Ed25519; the member's Ed25519 signing key then stays in key.pem and the TLS key
goes to tls.key). Verification reads both, so nothing else changes.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from ipaddress import IPv4Address
from pathlib import Path
from typing import Any

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from gmmap.errors import CredentialsError, CredentialsFileError, UntrustedMemberError
from gmmap.fleet.security.pki import (
    CA_CERT,
    CA_KEY,
    CERT,
    CRL,
    ISSUED,
    KEY,
    MEMBER_JSON,
    PEERS,
    ROLES,
    SIGNING_KEY_OID,
    SKEW,
    TLS_KEY_FILE,
    Member,
    attribute,
    cert_pem,
    check_name,
    load_cert,
    load_crl,
    load_private_key,
    member_of,
    private_pem,
    replace_file,
    spki,
    utcnow,
    write_new,
)

TLS_KEY = "ed25519"  # or "p256": the CA's and the members' TLS key type (module docstring)
CA_DAYS = 3650
MEMBER_DAYS = 5 * 365  # never past the CA's own expiry
CRL_DAYS = 365  # a CRL past its next update is refused: `refresh_crl` re-signs it
RESERVED = frozenset({CA_KEY, CA_CERT, CRL, ISSUED})  # names that would clash in DIR

CaKey = Ed25519PrivateKey | ec.EllipticCurvePrivateKey


def new_tls_key() -> CaKey:
    """A key for a TLS certificate (the CA's, a member's), of the type TLS_KEY names."""
    if TLS_KEY == "p256":
        return ec.generate_private_key(ec.SECP256R1())
    if TLS_KEY == "ed25519":
        return Ed25519PrivateKey.generate()
    raise CredentialsError(f"TLS_KEY must be 'ed25519' or 'p256'; got {TLS_KEY!r}")


def _member_tls_key(signing: Ed25519PrivateKey) -> CaKey:
    # Ed25519 TLS: one key does both (seal signatures carry their own domain prefix).
    return signing if TLS_KEY == "ed25519" else new_tls_key()


def _hash_for(key: CaKey) -> hashes.HashAlgorithm | None:
    return None if isinstance(key, Ed25519PrivateKey) else hashes.SHA256()


@dataclass(frozen=True)
class Authority:
    """A fleet's CA (``DIR``, made by `init_fleet`)."""

    dir: Path
    fleet: str
    certificate: x509.Certificate = field(repr=False)
    crl: x509.CertificateRevocationList = field(repr=False)
    key: CaKey = field(repr=False)

    def revoked(self, serial: int) -> bool:
        return self.crl.get_revoked_certificate_by_serial_number(serial) is not None


def load_authority(dir: Path) -> Authority:
    dir = Path(dir)
    if not (dir / CA_CERT).exists() and not (dir / CA_KEY).exists():
        raise CredentialsFileError(f"{dir}: no fleet authority here (gmmap fleet init {dir})")
    key, cert = load_private_key(dir / CA_KEY), load_cert(dir / CA_CERT)
    if spki(key.public_key()) != spki(cert.public_key()):
        raise CredentialsFileError(f"{dir / CA_KEY} does not match {dir / CA_CERT}")
    fleet = attribute(cert.subject, NameOID.COMMON_NAME) or ""
    crl = load_crl(dir / CRL)
    if crl.issuer != cert.subject or not crl.is_signature_valid(cert.public_key()):
        raise CredentialsFileError(f"{dir / CRL} was not signed by {dir / CA_CERT}")
    return Authority(dir, fleet, cert, crl, key)


def _ca_certificate(key: CaKey, fleet: str, days: int) -> x509.Certificate:
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, fleet)])
    now = utcnow()
    usage = x509.KeyUsage(False, False, False, False, False, True, True, False, False)
    return (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - SKEW)
        .not_valid_after(now + timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(usage, critical=True)  # keyCertSign + cRLSign only
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), False)
        .sign(key, _hash_for(key))
    )


def _member_folders(dir: Path) -> list[Path]:
    # Hidden folders are add_member's work in progress.
    return [
        p
        for p in sorted(dir.iterdir())
        if p.is_dir() and not p.name.startswith(".") and (p / MEMBER_JSON).is_file()
    ]


def _crl_number(crl: x509.CertificateRevocationList) -> int:
    try:
        return crl.extensions.get_extension_for_class(x509.CRLNumber).value.crl_number
    except x509.ExtensionNotFound:
        return 0


def _write_crl(
    dir: Path, key: CaKey, ca: x509.Certificate, serials: dict[int, datetime], number: int
) -> x509.CertificateRevocationList:
    """Sign CRL ``number`` (``serials``: revoked serial → when) and refresh every member's
    copy."""
    now = utcnow()
    builder = (
        x509.CertificateRevocationListBuilder()
        .issuer_name(ca.subject)
        .last_update(now - SKEW)
        .next_update(now + timedelta(days=CRL_DAYS))
        .add_extension(x509.CRLNumber(number), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(key.public_key()), False)
    )
    for serial, when in sorted(serials.items()):
        entry = x509.RevokedCertificateBuilder().serial_number(serial).revocation_date(when)
        builder = builder.add_revoked_certificate(entry.build())
    crl = builder.sign(key, _hash_for(key))
    pem = crl.public_bytes(serialization.Encoding.PEM)
    replace_file(dir / CRL, pem)
    for folder in _member_folders(dir):
        replace_file(folder / CRL, pem)
    return crl


def _resign_crl(auth: Authority, serials: dict[int, datetime]) -> x509.CertificateRevocationList:
    number = _crl_number(auth.crl) + 1
    return _write_crl(auth.dir, auth.key, auth.certificate, serials, number)


def _revoked_serials(crl: x509.CertificateRevocationList) -> dict[int, datetime]:
    return {r.serial_number: r.revocation_date_utc for r in crl}


def init_fleet(dir: Path, fleet: str, *, days: int = CA_DAYS) -> Authority:
    """A new fleet authority in ``dir``: CA key and certificate, an empty CRL."""
    dir = Path(dir)
    check_name("fleet name", fleet)
    if any((dir / f).exists() for f in (CA_KEY, CA_CERT, CRL)):
        raise CredentialsError(f"{dir} already holds a fleet authority")
    dir.mkdir(mode=0o700, parents=True, exist_ok=True)
    (dir / ISSUED).mkdir(exist_ok=True)
    key = new_tls_key()
    cert = _ca_certificate(key, fleet, days)
    write_new(dir / CA_KEY, private_pem(key), 0o600)
    write_new(dir / CA_CERT, cert_pem(cert), 0o644)
    _write_crl(dir, key, cert, {}, 1)
    return load_authority(dir)


def _member_certificate(
    auth: Authority, name: str, role: str, tls: Any, signing: Ed25519PublicKey, days: int
) -> x509.Certificate:
    ca = auth.certificate
    now = utcnow()
    subject = x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATIONAL_UNIT_NAME, role),
            x509.NameAttribute(NameOID.COMMON_NAME, name),
        ]
    )
    san = x509.SubjectAlternativeName(
        [x509.DNSName(name), x509.IPAddress(IPv4Address("127.0.0.1"))]
    )
    usage = x509.KeyUsage(True, False, False, False, False, False, False, False, False)
    eku = x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH])
    return (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(ca.subject)
        .public_key(tls)
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - SKEW)
        .not_valid_after(min(now + timedelta(days=days), ca.not_valid_after_utc))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(usage, critical=True)  # digitalSignature only
        .add_extension(eku, critical=False)
        .add_extension(san, critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(tls), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(auth.key.public_key()), False
        )
        .add_extension(x509.UnrecognizedExtension(SIGNING_KEY_OID, spki(signing)), False)
        .sign(auth.key, _hash_for(auth.key))
    )


def _check_new_member(auth: Authority, name: str, role: str, force: bool) -> None:
    check_name("member name", name)
    if name in RESERVED:
        raise CredentialsError(f"{name!r} is reserved for the authority's own files")
    if role not in ROLES:
        raise CredentialsError(f"role must be one of {', '.join(ROLES)}; got {role!r}")
    folder = auth.dir / name
    if not folder.exists():
        return
    if not (folder / CERT).is_file():
        raise CredentialsError(f"{folder} exists and is not a member folder")
    if not auth.revoked(load_cert(folder / CERT).serial_number):
        raise CredentialsError(
            f"member {name!r} already exists in fleet {auth.fleet!r} (revoke it first)"
        )
    if not force:
        raise CredentialsError(
            f"member {name!r} was revoked; add it with force (--force) for a new key and "
            "certificate"
        )


def _write_member(auth: Authority, folder: Path, name: str, role: str, days: int) -> bytes:
    """Key, certificate and copies into a new ``folder``; the certificate's PEM."""
    signing = Ed25519PrivateKey.generate()
    tls = _member_tls_key(signing)
    cert = _member_certificate(auth, name, role, tls.public_key(), signing.public_key(), days)
    pem = cert_pem(cert)
    folder.mkdir(mode=0o700)
    os.chmod(folder, 0o700)
    write_new(folder / KEY, private_pem(signing), 0o600)
    if tls is not signing:
        write_new(folder / TLS_KEY_FILE, private_pem(tls), 0o600)
    write_new(folder / CERT, pem, 0o644)
    shutil.copyfile(auth.dir / CA_CERT, folder / CA_CERT)
    shutil.copyfile(auth.dir / CRL, folder / CRL)
    info = {"fleet": auth.fleet, "name": name, "role": role}
    write_new(folder / MEMBER_JSON, (json.dumps(info, indent=2) + "\n").encode(), 0o644)
    # Every member known now (revoked ones too: a robot then knows why it refuses them).
    (folder / PEERS).mkdir()
    for other in _member_folders(auth.dir):
        if other.name != name:
            shutil.copyfile(other / CERT, folder / PEERS / f"{other.name}.pem")
    write_new(folder / PEERS / f"{name}.pem", pem, 0o644)
    write_new(auth.dir / ISSUED / f"{cert.serial_number:x}.pem", pem, 0o644)
    return pem


def add_member(
    dir: Path, name: str, role: str = "robot", *, force: bool = False, days: int = MEMBER_DAYS
) -> Path:
    """Issue member ``name``'s key and certificate into ``dir/name`` (see the module docstring);
    ``force`` replaces a revoked member of that name. Returns the member's folder."""
    auth = load_authority(dir)
    _check_new_member(auth, name, role, force)
    final, tmp, old = (auth.dir / p for p in (name, f".{name}.new", f".{name}.old"))
    for stale in (tmp, old):
        shutil.rmtree(stale, ignore_errors=True)
    pem = _write_member(auth, tmp, name, role, days)
    # Built aside, then swapped in: a failure leaves no half-made member.
    if final.exists():
        final.rename(old)
    tmp.rename(final)
    shutil.rmtree(old, ignore_errors=True)
    for other in _member_folders(auth.dir):
        if other != final:
            (other / PEERS).mkdir(exist_ok=True)
            replace_file(other / PEERS / f"{name}.pem", pem)
    return final


def revoke(dir: Path, name: str) -> Member:
    """Revoke member ``name``'s certificate: its serial joins the CRL, which is re-signed and
    copied into every member folder. Returns what was revoked."""
    auth = load_authority(dir)
    check_name("member name", name)
    cert_path = auth.dir / name / CERT
    if not cert_path.is_file():
        raise CredentialsError(f"fleet {auth.fleet!r} has no member {name!r} ({cert_path})")
    cert = load_cert(cert_path)
    if auth.revoked(cert.serial_number):
        raise CredentialsError(f"member {name!r} is already revoked")
    try:  # not verify_member: an expired member, or a stale CRL, may still be revoked
        cert.verify_directly_issued_by(auth.certificate)
    except (ValueError, TypeError, InvalidSignature):
        raise UntrustedMemberError(f"{cert_path} was not issued by this authority") from None
    member = member_of(cert, auth.fleet)
    _resign_crl(auth, _revoked_serials(auth.crl) | {cert.serial_number: utcnow()})
    return member


def refresh_crl(dir: Path) -> x509.CertificateRevocationList:
    """Re-sign the CRL with a new next update (it is refused once stale) and refresh the
    members' copies."""
    auth = load_authority(dir)
    return _resign_crl(auth, _revoked_serials(auth.crl))


def _status(auth: Authority, cert: x509.Certificate, current: set[int], now: datetime) -> str:
    if auth.revoked(cert.serial_number):
        return "revoked"
    if cert.not_valid_after_utc < now:
        return "expired"
    # Issued and not revoked, but its folder is gone (or holds a newer certificate).
    return "active" if cert.serial_number in current else "missing"


def describe(dir: Path) -> dict[str, Any]:
    """The fleet for ``gmmap fleet show``: every certificate issued, with its status (active,
    revoked, expired, missing)."""
    auth = load_authority(dir)
    now = utcnow()
    current = {load_cert(f / CERT).serial_number for f in _member_folders(auth.dir)}
    rows = []
    for path in sorted((auth.dir / ISSUED).glob("*.pem")):
        cert = load_cert(path)
        row = {
            "name": attribute(cert.subject, NameOID.COMMON_NAME),
            "role": attribute(cert.subject, NameOID.ORGANIZATIONAL_UNIT_NAME),
            "serial": f"{cert.serial_number:x}",
            "issued": cert.not_valid_before_utc.isoformat(),
            "expires": cert.not_valid_after_utc.isoformat(),
            "status": _status(auth, cert, current, now),
        }
        rows.append(row)
    # A re-added name: its revoked certificates first, then the one in use.
    rows.sort(key=lambda r: (r["name"] or "", r["issued"], r["status"] == "active"))
    next_update = auth.crl.next_update_utc
    return {
        "fleet": auth.fleet,
        "dir": str(auth.dir),
        "ca_expires": auth.certificate.not_valid_after_utc.isoformat(),
        "crl_number": _crl_number(auth.crl),
        "crl_next_update": next_update.isoformat() if next_update else None,
        "revoked_serials": len(auth.crl),
        "members": rows,
    }
