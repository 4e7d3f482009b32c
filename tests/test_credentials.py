"""Fleet credentials (`gmmap.fleet.security.credentials`) and ``gmmap fleet``: issuing, loading,
revoking, and refusing what the fleet's authority did not issue."""

import json
import os
import stat
from datetime import datetime, timedelta, timezone
from ipaddress import IPv4Address

import pytest
from click.testing import CliRunner
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from gmmap.cli import main
from gmmap.errors import (
    CredentialsError,
    CredentialsFileError,
    GmmapError,
    InsecureKeyError,
    RefusedError,
    RevokedMemberError,
    UntrustedMemberError,
)
from gmmap.fleet.security import authority, credentials
from gmmap.fleet.security.credentials import (
    SIGNING_KEY_OID,
    add_member,
    describe,
    init_fleet,
    load,
    refresh_crl,
    revoke,
    verify_member,
)

posix_only = pytest.mark.skipif(os.name != "posix", reason="file modes are POSIX")


def mode(path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


@pytest.fixture
def fleet(tmp_path):
    """Fleet "lab" with robot a and station base."""
    d = tmp_path / "keys"
    init_fleet(d, "lab")
    add_member(d, "a")
    add_member(d, "base", role="station")
    return d


def check(creds, cert_pem: bytes):
    return verify_member(cert_pem, creds.ca, creds.crl, creds.fleet)


# ----------------------------------------------------------------------------- round trips


@posix_only
def test_init_writes_the_authority_with_private_modes(tmp_path):
    d = tmp_path / "keys"
    auth = init_fleet(d, "lab")
    assert auth.fleet == "lab"
    assert mode(d) == 0o700 and mode(d / "ca.key") == 0o600
    ca = x509.load_pem_x509_certificate((d / "ca.pem").read_bytes())
    assert ca.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == "lab"
    basic = ca.extensions.get_extension_for_class(x509.BasicConstraints)
    assert basic.critical and basic.value.ca
    usage = ca.extensions.get_extension_for_class(x509.KeyUsage).value
    assert usage.key_cert_sign and usage.crl_sign and not usage.digital_signature
    ca.extensions.get_extension_for_class(x509.SubjectKeyIdentifier)
    assert ca.not_valid_after_utc - ca.not_valid_before_utc > timedelta(days=9 * 365)
    crl = x509.load_pem_x509_crl((d / "crl.pem").read_bytes())
    assert len(crl) == 0 and crl.is_signature_valid(ca.public_key())
    assert serialization.load_pem_private_key((d / "ca.key").read_bytes(), None)


def test_init_refuses_an_existing_fleet_and_bad_names(tmp_path):
    init_fleet(tmp_path / "keys", "lab")
    with pytest.raises(CredentialsError, match="already holds a fleet"):
        init_fleet(tmp_path / "keys", "other")
    for bad in ("", "a/b", "-lab", "lab*", "x" * 65, "la b"):
        with pytest.raises(CredentialsError, match="fleet name"):
            init_fleet(tmp_path / "k2", bad)
    assert not (tmp_path / "k2").exists()


@posix_only
def test_add_issues_a_member_folder(fleet):
    folder = fleet / "a"
    assert mode(folder) == 0o700 and mode(folder / "key.pem") == 0o600
    assert json.loads((folder / "member.json").read_text()) == {
        "fleet": "lab",
        "name": "a",
        "role": "robot",
    }
    assert (folder / "ca.pem").read_bytes() == (fleet / "ca.pem").read_bytes()
    assert (folder / "crl.pem").read_bytes() == (fleet / "crl.pem").read_bytes()
    assert not (folder / "tls.key").exists()  # Ed25519: key.pem is the TLS key too
    cert = x509.load_pem_x509_certificate((folder / "cert.pem").read_bytes())
    ext = cert.extensions
    assert cert.subject.rfc4514_string() == "CN=a,OU=robot"
    assert cert.issuer.rfc4514_string() == "CN=lab"
    san = ext.get_extension_for_class(x509.SubjectAlternativeName).value
    assert san.get_values_for_type(x509.DNSName) == ["a"]
    assert san.get_values_for_type(x509.IPAddress) == [IPv4Address("127.0.0.1")]
    assert not ext.get_extension_for_class(x509.BasicConstraints).value.ca
    assert ext.get_extension_for_class(x509.KeyUsage).value.digital_signature
    assert set(ext.get_extension_for_class(x509.ExtendedKeyUsage).value) == {
        ExtendedKeyUsageOID.SERVER_AUTH,
        ExtendedKeyUsageOID.CLIENT_AUTH,
    }
    assert not ext.get_extension_for_oid(SIGNING_KEY_OID).critical  # rustls ignores it
    base = x509.load_pem_x509_certificate((fleet / "base" / "cert.pem").read_bytes())
    assert base.subject.get_attributes_for_oid(NameOID.ORGANIZATIONAL_UNIT_NAME)[0].value == (
        "station"
    )


def test_load_sign_and_verify(fleet):
    a, base = load(fleet / "a"), load(fleet / "base")
    assert (a.fleet, a.name, a.role) == ("lab", "a", "robot")
    assert (base.name, base.role) == ("base", "station")
    assert a.tls_key_path == a.key_path == fleet / "a" / "key.pem"
    message = b"gmmap-seal-v1\0lab\0a\0submap\0" + bytes(range(200))
    signature = a.sign(message)
    assert len(signature) == 64
    member = check(base, (fleet / "a" / "cert.pem").read_bytes())
    assert (member.name, member.role, member.fleet) == ("a", "robot", "lab")
    assert member.verify(message, signature)
    assert not member.verify(message[:-1] + b"\xff", signature)  # altered bytes
    assert not member.verify(message, signature[:-1] + bytes([signature[-1] ^ 1]))
    assert not member.verify(message, b"short")
    assert not check(base, (fleet / "base" / "cert.pem").read_bytes()).verify(message, signature)


def test_peers_know_each_other_and_later_members(fleet):
    a = load(fleet / "a")
    assert a.roster.names() == ["a", "base"]
    add_member(fleet, "c")
    a = load(fleet / "a")  # c's certificate was added to a's peers/
    c = load(fleet / "c")
    assert a.roster.names() == ["a", "base", "c"]
    signature = c.sign(b"hello")
    a.member_key("c").verify(signature, b"hello")
    assert a.member_key("nobody") is None


def test_learn_takes_a_member_and_refuses_a_stranger(fleet, tmp_path):
    add_member(fleet, "c")
    (fleet / "a" / "peers" / "c.pem").unlink()  # a was deployed before c was added
    a = load(fleet / "a")
    assert a.member_key("c") is None
    assert a.learn((fleet / "c" / "cert.pem").read_bytes()).name == "c"
    assert a.member_key("c") is not None
    init_fleet(tmp_path / "other", "lab")
    add_member(tmp_path / "other", "d")
    with pytest.raises(UntrustedMemberError):
        a.learn((tmp_path / "other" / "d" / "cert.pem").read_bytes())
    assert a.member_key("d") is None


# ----------------------------------------------------------------------------- add refuses


def test_add_refuses_duplicates_bad_roles_and_names(fleet, tmp_path):
    with pytest.raises(CredentialsError, match="already exists"):
        add_member(fleet, "a")
    with pytest.raises(CredentialsError, match="already exists"):
        add_member(fleet, "a", force=True)  # force only replaces a revoked member
    with pytest.raises(CredentialsError, match="role"):
        add_member(fleet, "b", role="admin")
    for bad in ("a/b", "../x", ".hidden", "*"):
        with pytest.raises(CredentialsError, match="member name"):
            add_member(fleet, bad)
    for reserved in ("ca.pem", "crl.pem", "issued"):
        with pytest.raises(CredentialsError, match="reserved"):
            add_member(fleet, reserved)
    with pytest.raises(CredentialsFileError, match="no fleet authority"):
        add_member(tmp_path / "nowhere", "a")


def test_a_revoked_name_comes_back_only_with_force(fleet):
    old = load(fleet / "a").certificate.serial_number
    revoke(fleet, "a")
    with pytest.raises(CredentialsError, match="--force"):
        add_member(fleet, "a")
    add_member(fleet, "a", force=True)
    a = load(fleet / "a")
    assert a.certificate.serial_number != old
    assert load(fleet / "base").member_key("a") == a.member_key("a")
    crl = x509.load_pem_x509_crl((fleet / "crl.pem").read_bytes())
    assert crl.get_revoked_certificate_by_serial_number(old) is not None
    statuses = [(m["name"], m["status"]) for m in describe(fleet)["members"]]
    assert statuses == [("a", "revoked"), ("a", "active"), ("base", "active")]
    assert not list(fleet.glob(".*"))  # no work-in-progress folders left


# ----------------------------------------------------------------------------- revocation


def test_revoke_refuses_the_member_everywhere(fleet):
    a_cert = (fleet / "a" / "cert.pem").read_bytes()
    member = revoke(fleet, "a")
    assert (member.name, member.role) == ("a", "robot")
    crl_pem = (fleet / "crl.pem").read_bytes()
    assert (fleet / "a" / "crl.pem").read_bytes() == crl_pem
    assert (fleet / "base" / "crl.pem").read_bytes() == crl_pem
    crl = x509.load_pem_x509_crl(crl_pem)
    assert crl.get_revoked_certificate_by_serial_number(member.serial) is not None
    assert crl.next_update_utc > datetime.now(timezone.utc) + timedelta(days=300)
    base = load(fleet / "base")
    with pytest.raises(RevokedMemberError, match="revoked"):
        check(base, a_cert)
    with pytest.raises(RefusedError) as refused:
        base.member_key("a")
    assert refused.value.cause == "revoked"
    with pytest.raises(RevokedMemberError):
        load(fleet / "a")  # a revoked robot does not start
    with pytest.raises(CredentialsError, match="already revoked"):
        revoke(fleet, "a")
    with pytest.raises(CredentialsError, match="no member"):
        revoke(fleet, "zzz")


def test_a_stale_crl_is_refused_and_refresh_renews_it(fleet):
    base = load(fleet / "base")
    a_cert = (fleet / "a" / "cert.pem").read_bytes()
    later = base.crl.next_update_utc + timedelta(days=1)
    with pytest.raises(UntrustedMemberError, match="stale"):
        verify_member(a_cert, base.ca, base.crl, "lab", now=later)
    before = describe(fleet)["crl_number"]
    refresh_crl(fleet)
    assert describe(fleet)["crl_number"] == before + 1
    assert (fleet / "base" / "crl.pem").read_bytes() == (fleet / "crl.pem").read_bytes()


def test_an_expired_member_is_refused(fleet):
    add_member(fleet, "short", days=1)
    base = load(fleet / "base")
    cert = (fleet / "short" / "cert.pem").read_bytes()
    assert check(base, cert).name == "short"
    in_two_days = datetime.now(timezone.utc) + timedelta(days=2)
    with pytest.raises(UntrustedMemberError, match="not now"):
        verify_member(cert, base.ca, base.crl, "lab", now=in_two_days)


# ----------------------------------------------------------------------------- strangers


def test_a_member_of_another_fleet_is_refused(fleet, tmp_path):
    """Another CA, even one with the same fleet name and member name."""
    other = tmp_path / "other"
    init_fleet(other, "lab")
    add_member(other, "a")
    base = load(fleet / "base")
    with pytest.raises(UntrustedMemberError, match="not issued by") as refused:
        check(base, (other / "a" / "cert.pem").read_bytes())
    assert not isinstance(refused.value, RevokedMemberError)
    init_fleet(tmp_path / "third", "field")
    add_member(tmp_path / "third", "a")
    with pytest.raises(UntrustedMemberError):
        check(base, (tmp_path / "third" / "a" / "cert.pem").read_bytes())


def test_a_forged_certificate_is_refused(fleet):
    """Self-signed, with the same CN, role, issuer name and extensions as a real member."""
    real = x509.load_pem_x509_certificate((fleet / "a" / "cert.pem").read_bytes())
    key = Ed25519PrivateKey.generate()
    builder = (
        x509.CertificateBuilder()
        .subject_name(real.subject)
        .issuer_name(real.issuer)
        .public_key(key.public_key())
        .serial_number(real.serial_number)
        .not_valid_before(real.not_valid_before_utc)
        .not_valid_after(real.not_valid_after_utc)
    )
    for ext in real.extensions:
        if ext.oid != SIGNING_KEY_OID:
            builder = builder.add_extension(ext.value, ext.critical)
    spki = key.public_key().public_bytes(
        serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    )
    builder = builder.add_extension(x509.UnrecognizedExtension(SIGNING_KEY_OID, spki), False)
    forged = builder.sign(key, None).public_bytes(serialization.Encoding.PEM)
    with pytest.raises(UntrustedMemberError, match="not issued by"):
        check(load(fleet / "base"), forged)


def test_the_ca_certificate_is_no_member(fleet):
    with pytest.raises(UntrustedMemberError, match="no member certificate"):
        check(load(fleet / "base"), (fleet / "ca.pem").read_bytes())


@pytest.mark.parametrize(
    "data",
    [b"", b"garbage", b"-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n"],
)
def test_garbage_peer_pem_is_untrusted(fleet, data):
    with pytest.raises(UntrustedMemberError, match="not a PEM certificate"):
        check(load(fleet / "base"), data)


def test_truncated_peer_pem_is_untrusted(fleet):
    pem = (fleet / "a" / "cert.pem").read_bytes()
    with pytest.raises(UntrustedMemberError, match="not a PEM certificate"):
        check(load(fleet / "base"), pem[: len(pem) // 2])


# ----------------------------------------------------------------------------- broken files


@pytest.mark.parametrize("name", ["cert.pem", "key.pem", "ca.pem", "crl.pem", "member.json"])
def test_truncated_or_missing_files_are_typed_errors(fleet, name):
    path = fleet / "a" / name
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CredentialsFileError, match=name):
        load(fleet / "a")
    path.unlink()
    with pytest.raises(CredentialsFileError, match="missing"):
        load(fleet / "a")


@posix_only
@pytest.mark.parametrize("bits", [0o640, 0o604, 0o644])
def test_a_readable_key_is_refused_like_ssh(fleet, bits):
    os.chmod(fleet / "a" / "key.pem", bits)
    with pytest.raises(InsecureKeyError, match="chmod 600"):
        load(fleet / "a")
    os.chmod(fleet / "ca.key", bits)
    with pytest.raises(InsecureKeyError):
        add_member(fleet, "c")


def test_a_key_that_does_not_match_its_certificate(fleet):
    a = fleet / "a"
    (a / "key.pem").unlink()
    (a / "key.pem").write_bytes((fleet / "base" / "key.pem").read_bytes())
    os.chmod(a / "key.pem", 0o600)
    with pytest.raises(CredentialsFileError, match="does not match"):
        load(a)


def test_a_certificate_from_another_ca_in_the_folder(fleet, tmp_path):
    other = tmp_path / "other"
    init_fleet(other, "lab")
    add_member(other, "a")
    for name in ("cert.pem", "key.pem"):
        (fleet / "a" / name).write_bytes((other / "a" / name).read_bytes())
    with pytest.raises(UntrustedMemberError, match="not issued by"):
        load(fleet / "a")


def test_a_crl_of_another_ca_is_refused(fleet, tmp_path):
    init_fleet(tmp_path / "other", "lab")
    (fleet / "a" / "crl.pem").write_bytes((tmp_path / "other" / "crl.pem").read_bytes())
    with pytest.raises(CredentialsFileError, match="CRL was not signed"):
        load(fleet / "a")


def test_member_json_must_match_the_certificate(fleet):
    (fleet / "a" / "member.json").write_text('{"fleet": "lab", "name": "a", "role": "station"}')
    with pytest.raises(CredentialsFileError, match="names a"):
        load(fleet / "a")


def test_errors_are_value_errors():
    for cls in (CredentialsError, CredentialsFileError, InsecureKeyError, UntrustedMemberError):
        assert issubclass(cls, GmmapError) and issubclass(cls, ValueError)
    assert issubclass(RevokedMemberError, UntrustedMemberError)


# ----------------------------------------------------------------------------- key switch


def test_p256_tls_keys_keep_ed25519_signing(tmp_path, monkeypatch):
    """The switch for a TLS stack that refuses Ed25519 (authority.TLS_KEY)."""
    monkeypatch.setattr(authority, "TLS_KEY", "p256")
    d = tmp_path / "keys"
    init_fleet(d, "lab")
    add_member(d, "a")
    add_member(d, "b")
    a, b = load(d / "a"), load(d / "b")
    assert a.tls_key_path == d / "a" / "tls.key" and mode(a.tls_key_path) == 0o600
    assert isinstance(a.certificate.public_key(), ec.EllipticCurvePublicKey)
    assert isinstance(a.ca.public_key(), ec.EllipticCurvePublicKey)
    assert isinstance(a.private_key, Ed25519PrivateKey)
    assert b.member_key("a") is not None
    assert check(b, a.certificate).verify(b"x", a.sign(b"x"))
    revoke(d, "a")
    with pytest.raises(RevokedMemberError):
        check(load(d / "b"), a.certificate)
    # A fleet issued under one setting loads under the other.
    monkeypatch.setattr(authority, "TLS_KEY", "ed25519")
    assert load(d / "b").name == "b"


# ----------------------------------------------------------------------------- the CLI


def cli(*args, ok=True):
    result = CliRunner().invoke(main, ["fleet", *map(str, args)])
    assert (result.exit_code == 0) == ok, result.output
    return result


def test_cli_init_add_revoke_show(tmp_path):
    d = tmp_path / "keys"
    assert "authority in" in cli("init", d, "--fleet", "lab").output
    assert "copy that folder" in cli("add", d, "a").output
    cli("add", d, "base", "--role", "station")
    assert "revoked robot 'a'" in cli("revoke", d, "a").output
    cli("add", d, "a", "--force")
    cli("refresh", d)
    shown = json.loads(cli("show", d, "--json").stdout)
    assert shown["fleet"] == "lab" and shown["revoked_serials"] == 1
    rows = [(m["name"], m["role"], m["status"]) for m in shown["members"]]
    assert rows == [
        ("a", "robot", "revoked"),
        ("a", "robot", "active"),
        ("base", "station", "active"),
    ]
    table = cli("show", d).stdout
    assert "fleet lab" in table and "station" in table and "revoked" in table
    assert load(d / "a").role == "robot"


def test_cli_errors_are_one_line(tmp_path):
    d = tmp_path / "keys"
    cli("init", d, "--fleet", "lab")
    for args, text in [
        (("init", d, "--fleet", "lab"), "already holds a fleet"),
        (("add", d, "bad/name"), "member name"),
        (("revoke", d, "nobody"), "no member"),
        (("show", tmp_path / "nowhere"), "no fleet authority"),
        (("init", tmp_path / "k2", "--fleet", "a b"), "fleet name"),
    ]:
        out = cli(*args, ok=False).output
        assert out.startswith("Error: ") and text in out and "Traceback" not in out
    assert "not one of" in cli("add", d, "b", "--role", "admin", ok=False).output


def test_cli_help():
    out = cli("--help").output
    for name in ("init", "add", "revoke", "show", "refresh"):
        assert name in out
    assert "--force" in cli("add", "--help").output
    assert "--fleet" in cli("init", "--help").output
    assert credentials.ROLES == ("robot", "station")
