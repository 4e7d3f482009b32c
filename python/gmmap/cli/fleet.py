"""``gmmap fleet``: the fleet's credentials: an authority (CA), member keys and certificates,
revocation (`gmmap.fleet.security.credentials`)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from gmmap.cli.common import as_json_option, log

FLEET_DIR = click.argument("dir", type=click.Path(file_okay=False, path_type=Path))
MEMBER = click.argument("name", metavar="ROBOT")


@click.group("fleet")
def command() -> None:
    """Fleet credentials: one authority per fleet, one key and certificate per robot.

    \b
    gmmap fleet init keys/ --fleet lab   # the authority: keys/ca.key (keep it), ca.pem, crl.pem
    gmmap fleet add keys/ a              # keys/a/: copy this folder, and only it, to robot a
    gmmap fleet revoke keys/ a           # a's certificate joins the CRL; every member folder's
                                         # crl.pem is refreshed: copy them to the robots again
    gmmap fleet show keys/               # members, roles, status, expiry

    Keys are Ed25519; private keys are written 0600 and refused when group or others can read
    them. A member's folder holds its key and certificate, the CA certificate, the CRL and the
    certificates of the members known when it was added (peers/).
    """


@command.command("init")
@FLEET_DIR
@click.option("--fleet", "fleet", required=True, help="The fleet's name (the CA's CN).")
def init(dir: Path, fleet: str) -> None:
    """Create fleet FLEET's authority in DIR.

    The authority is a CA key and certificate and an empty CRL. DIR may exist but must not
    hold a fleet already. The CA key (DIR/ca.key) signs every member certificate and
    revocation: keep DIR off the robots.
    """
    from gmmap.fleet.security.credentials import init_fleet

    authority = init_fleet(dir, fleet)
    expires = authority.certificate.not_valid_after_utc
    log(f"fleet {fleet!r}: authority in {dir} (CA valid until {expires:%Y-%m-%d})")


@command.command("add")
@FLEET_DIR
@MEMBER
@click.option(
    "--role",
    type=click.Choice(["robot", "station"]),
    default="robot",
    show_default=True,
    help="The member's role, certified in its certificate (OU).",
)
@click.option("--force", is_flag=True, help="Re-add a revoked member: a new key and certificate.")
def add(dir: Path, name: str, role: str, force: bool) -> None:
    """Issue member ROBOT's key and certificate into DIR/ROBOT.

    Copy DIR/ROBOT to the robot and run it with that folder (gmmap robot --credentials).
    The earlier members' peers/ get ROBOT's certificate: copy their folders again and
    restart those robots to let ROBOT in. A name in use is refused; a revoked one needs
    --force.
    """
    from gmmap.fleet.security.credentials import add_member

    folder = add_member(dir, name, role, force=force)
    log(f"added {role} {name!r} → {folder} (copy that folder to the robot)")


@command.command("revoke")
@FLEET_DIR
@MEMBER
def revoke(dir: Path, name: str) -> None:
    """Revoke member ROBOT: its certificate joins the fleet's CRL.

    The CRL is re-signed and every member folder's crl.pem refreshed: copy them to the
    robots. A running robot takes its folder's new crl.pem in within seconds and refuses
    ROBOT's submaps from then on.
    """
    from gmmap.fleet.security.credentials import revoke as revoke_member

    member = revoke_member(dir, name)
    log(f"revoked {member.role} {name!r} (serial {member.serial:x}); copy the crl.pem files")


@command.command("refresh")
@FLEET_DIR
def refresh(dir: Path) -> None:
    """Re-sign the CRL with a new next update.

    Robots refuse every peer once the CRL is stale (a year after it was signed).
    """
    from gmmap.fleet.security.credentials import refresh_crl

    crl = refresh_crl(dir)
    log(f"CRL re-signed, next update {crl.next_update_utc:%Y-%m-%d}; copy the crl.pem files")


@command.command("show")
@FLEET_DIR
@as_json_option
def show(dir: Path, as_json: bool) -> None:
    """List the members: role, serial, expiry, status.

    Every certificate DIR's authority issued, with its status: active, revoked, expired, or
    missing (not revoked, but its member folder is gone).
    """
    from gmmap.fleet.security.credentials import describe

    fleet = describe(dir)
    if as_json:
        click.echo(json.dumps(fleet))
        return
    click.echo(
        f"fleet {fleet['fleet']}: CA until {fleet['ca_expires'][:10]}, CRL #{fleet['crl_number']} "
        f"({fleet['revoked_serials']} revoked) until {(fleet['crl_next_update'] or '?')[:10]}"
    )
    click.echo(f"{'member':<20} {'role':<8} {'serial':<16} {'expires':<10}  status")
    for m in fleet["members"]:
        click.echo(
            f"{m['name']:<20} {m['role']:<8} {m['serial'][:16]:<16} {m['expires'][:10]}  "
            f"{m['status']}"
        )
