"""Fleet credentials: a fleet authority (a CA), one key and certificate per member, a revocation
list, and the checks a robot makes of its own files and of its peers' certificates. All crypto
is the `cryptography` package's; nothing here is hand-made.

Layout (``gmmap fleet init DIR`` / ``add`` / ``revoke``)::

    DIR/ca.key            the authority's private key (PKCS8 PEM, 0600): never leaves DIR
    DIR/ca.pem            the self-signed CA certificate (CN = fleet name)
    DIR/crl.pem           the revocation list, signed by the CA (next update: CRL_DAYS)
    DIR/issued/SERIAL.pem every certificate ever issued (hex serial), for `describe`
    DIR/NAME/             one member (0700): copy this folder, and only it, to the robot
        key.pem           the member's Ed25519 signing key (PKCS8 PEM, 0600)
        tls.key           the TLS key, only where TLS_KEY is not "ed25519" (else key.pem is it)
        cert.pem          the member certificate, issued by the CA
        ca.pem, crl.pem   copies of the authority's (revoke refreshes every crl.pem)
        peers/NAME.pem    the certificates of the fleet's members when this one was added (and
                          this member's certificate is added to every earlier member's peers/)
        member.json       {"fleet", "name", "role"}

A member certificate: subject ``OU=<role>, CN=<name>`` (the role is the single OU: "robot" or
"station"), SAN DNS:<name> and IP:127.0.0.1, basicConstraints CA=false, keyUsage
digitalSignature, extendedKeyUsage serverAuth+clientAuth, and the member's Ed25519 signing key
as a SubjectPublicKeyInfo in the non-critical extension SIGNING_KEY_OID. Peers read the signing
key from that extension whatever the TLS key is, so the CA binds name, role and signing key in
one signature.

TLS key type: `gmmap.fleet.security.authority.TLS_KEY` = "ed25519" makes the CA key and every
member's TLS key Ed25519, and the member's signing key is its TLS key. TLS_KEY = "p256" (should
rustls refuse Ed25519) makes them ECDSA P-256 (SHA-256 signatures) and writes the TLS key to
tls.key; signing stays Ed25519 in key.pem. `load` and `verify_member` read both layouts, so fleets
of either kind keep working.

Re-adding a revoked name needs ``force`` (``--force``): it issues a new key and certificate
under a new serial; the old serial stays in the CRL. An active member is never replaced: revoke
it first.
"""

from __future__ import annotations

import json
import logging
import threading
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey
from cryptography.x509.oid import NameOID

from gmmap.errors import (
    CredentialsError,
    CredentialsFileError,
    RefusedError,
    RevokedMemberError,
    UntrustedMemberError,
)
from gmmap.fleet.security.authority import (
    CA_DAYS,
    CRL_DAYS,
    MEMBER_DAYS,
    Authority,
    add_member,
    describe,
    init_fleet,
    load_authority,
    refresh_crl,
    revoke,
)
from gmmap.fleet.security.pki import (
    CA_CERT,
    CERT,
    CRL,
    KEY,
    MEMBER_JSON,
    PEERS,
    ROLES,
    SIGNING_KEY_OID,
    TLS_KEY_FILE,
    Member,
    attribute,
    check_authority,
    check_name,
    load_cert,
    load_crl,
    load_private_key,
    read_file,
    spki,
    verify_member,
)

__all__ = [
    "CA_DAYS",
    "CRL_DAYS",
    "MEMBER_DAYS",
    "ROLES",
    "SIGNING_KEY_OID",
    "Authority",
    "Credentials",
    "Member",
    "Roster",
    "add_member",
    "describe",
    "init_fleet",
    "load",
    "load_authority",
    "load_for",
    "refresh_crl",
    "revoke",
    "verify_member",
]

log = logging.getLogger(__name__)


class Roster:
    """The members a robot knows by name: ``peers/`` at `load`, and those learned since
    (`Credentials.learn`). Thread-safe: the transport's callbacks look keys up."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._members: dict[str, Member] = {}
        self._revoked: set[str] = set()

    def add(self, member: Member) -> None:
        with self._lock:
            known = self._members.get(member.name)
            # A re-issued name (add --force) has a later certificate: keep the newest.
            if known is None or member.certificate.not_valid_before_utc >= (
                known.certificate.not_valid_before_utc
            ):
                self._members[member.name] = member
                self._revoked.discard(member.name)

    def mark_revoked(self, name: str) -> None:
        """A name whose certificate the CRL revokes (a later `add` of that name clears it)."""
        with self._lock:
            if name not in self._members:
                self._revoked.add(name)

    def revoke(self, crl: x509.CertificateRevocationList) -> list[str]:
        """Forgets the members ``crl`` revokes (a CRL checked by the caller); their names."""
        with self._lock:
            revoked = crl.get_revoked_certificate_by_serial_number
            gone = [n for n, m in self._members.items() if revoked(m.serial) is not None]
            for name in gone:
                del self._members[name]
                self._revoked.add(name)
        return gone

    def get(self, name: str) -> Member | None:
        with self._lock:
            return self._members.get(name)

    def names(self) -> list[str]:
        with self._lock:
            return sorted(self._members)

    def key(self, name: str) -> Ed25519PublicKey | None:
        """``name``'s signing key; None where unknown; `RefusedError` ("revoked") where the CRL
        revokes the only certificate known for it."""
        with self._lock:
            if name in self._revoked:
                raise RefusedError("revoked", f"{name} has been revoked from the fleet")
            member = self._members.get(name)
        return None if member is None else member.public_key


@dataclass(frozen=True)
class Credentials:
    """One member's credentials, checked (`load`): what the transport's TLS needs (paths) and
    what sealing needs (`sign`, `member_key`). The CRL is the one read at `load`: load again
    to take a new one in."""

    fleet: str
    name: str
    role: str
    dir: Path
    key_path: Path  # the Ed25519 signing key
    tls_key_path: Path  # the TLS key: key_path itself where TLS_KEY was "ed25519"
    cert_path: Path
    ca_path: Path
    crl_path: Path
    ca: x509.Certificate = field(repr=False)
    certificate: x509.Certificate = field(repr=False)
    crl: x509.CertificateRevocationList = field(repr=False)
    private_key: Ed25519PrivateKey = field(repr=False)
    roster: Roster = field(repr=False, compare=False, default_factory=Roster)

    def sign(self, message: bytes) -> bytes:
        """The Ed25519 signature (64 bytes) of ``message`` by this member's key."""
        return self.private_key.sign(message)

    def verify_peer(self, cert_pem: bytes | x509.Certificate) -> Member:
        """`verify_member` against this member's CA and CRL (those read at `load`)."""
        return verify_member(cert_pem, self.ca, self.crl, self.fleet)

    def learn(self, cert_pem: bytes | x509.Certificate) -> Member:
        """Check a peer's certificate (say, sent in-band) and remember it in the roster."""
        member = self.verify_peer(cert_pem)
        self.roster.add(member)
        return member

    def member_key(self, name: str) -> Ed25519PublicKey | None:
        """A member's signing key by name (`gmmap.fleet.security.seal.KeyLookup`)."""
        return self.roster.key(name)

    def reread_crl(self) -> list[str]:
        """Takes in ``crl.pem`` as it is now (``gmmap fleet revoke`` refreshes every member
        folder's copy), if the fleet's authority signed it: the names it newly revokes. A
        running robot refuses their submaps from then on; its links and access control keep
        them until it restarts (Zenoh fixes those when the session opens)."""
        crl = load_crl(self.crl_path)
        check_authority(self.ca, crl, self.fleet, datetime.now(timezone.utc))
        return self.roster.revoke(crl)


def _member_json(folder: Path) -> dict[str, str]:
    path = folder / MEMBER_JSON
    try:
        info = json.loads(read_file(path))
        fleet, name, role = info["fleet"], info["name"], info["role"]
    except (ValueError, TypeError, KeyError):
        raise CredentialsFileError(f"{path}: not a member description") from None
    check_name("fleet name", fleet)
    check_name("member name", name)
    if role not in ROLES:
        raise CredentialsFileError(f"{path}: role {role!r} is not one of {', '.join(ROLES)}")
    return {"fleet": fleet, "name": name, "role": role}


def _load_roster(
    folder: Path, ca: x509.Certificate, crl: x509.CertificateRevocationList, fleet: str
) -> Roster:
    roster = Roster()
    for path in sorted(folder.glob("*.pem")) if folder.is_dir() else []:
        cert = load_cert(path)
        try:
            roster.add(verify_member(cert, ca, crl, fleet))
        except RevokedMemberError:  # CA-signed (checked first), so its CN is the member's
            roster.mark_revoked(attribute(cert.subject, NameOID.COMMON_NAME) or path.stem)
        except UntrustedMemberError as err:  # expired, say: the others still count
            log.warning("%s: skipped: %s", path, err)
    return roster


def load(member_dir: Path) -> Credentials:
    """A member's folder (``DIR/NAME``), checked: key permissions, every file parses, the keys
    match the certificate, the certificate is the fleet CA's, valid and not revoked."""
    folder = Path(member_dir)
    info = _member_json(folder)
    key_path, tls_path, cert_path = folder / KEY, folder / TLS_KEY_FILE, folder / CERT
    signing = load_private_key(key_path)
    if not isinstance(signing, Ed25519PrivateKey):
        raise CredentialsFileError(f"{key_path}: not an Ed25519 key")
    if not tls_path.exists():
        tls_path = key_path
    tls = signing if tls_path == key_path else load_private_key(tls_path)
    cert, ca = load_cert(cert_path), load_cert(folder / CA_CERT)
    crl = load_crl(folder / CRL)
    if spki(tls.public_key()) != spki(cert.public_key()):
        raise CredentialsFileError(f"{tls_path} does not match {cert_path}")
    member = verify_member(cert, ca, crl, info["fleet"])
    if spki(member.public_key) != spki(signing.public_key()):
        raise CredentialsFileError(f"{key_path} is not the signing key {cert_path} names")
    if (member.name, member.role) != (info["name"], info["role"]):
        raise CredentialsFileError(
            f"{folder / MEMBER_JSON} names {info['name']} ({info['role']}), "
            f"{cert_path} {member.name} ({member.role})"
        )
    roster = _load_roster(folder / PEERS, ca, crl, info["fleet"])
    roster.add(member)
    return Credentials(
        info["fleet"], member.name, member.role, folder, key_path, tls_path, cert_path,
        folder / CA_CERT, folder / CRL, ca, cert, crl, signing, roster,
    )  # fmt: skip


def load_for(member_dir: Path, fleet: str, name: str) -> Credentials:
    """`load`, and `CredentialsError` unless the folder is ``name``'s of ``fleet``."""
    c = load(member_dir)
    if (c.fleet, c.name) != (fleet, name):
        raise CredentialsError(
            f"{member_dir} holds {c.name!r} of fleet {c.fleet!r}, not {name!r} of {fleet!r}"
        )
    return c
