"""A secured fleet's Zenoh configuration (`gmmap.fleet.net.session`): TLS links with mutual
authentication against the fleet's authority, and Zenoh's access control.

Every member holds a certificate of the fleet's authority whose common name is its name
(`gmmap.fleet.security.credentials`). Zenoh checks it in the TLS handshake, both ways: a process
without one, or with one of another authority, cannot open a link. Access control then
filters, on every robot, what comes in from each authenticated peer, by the common name of
its certificate; ``default_permission`` deny drops anything no rule allows, silently (Zenoh
logs it at trace level only). The rules:

- every member may subscribe and query under ``gmmap/<fleet>/**`` (read);
- a robot may put and hold its liveliness token only under its own name, and may answer
  queries for any robot of the fleet: a robot in between hands on the others' submaps, whose
  own seals (`gmmap.fleet.security.seal`) keep it from altering or forging them;
- a station (read-only) may do nothing else: it publishes nothing, answers nothing and is not
  seen as a robot;
- a revoked member, or a name the roster does not hold, matches no rule.

Zenoh's access control is fixed when the session opens: a member added to the fleet later is
let in by a robot once that robot restarts on the refreshed roster.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from gmmap.config import Config
from gmmap.names import PREFIX

READ = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]
RELAY = ["reply", "declare_queryable"]
OWN = ["put", "delete", "liveliness_token"]
EVERYTHING = READ + RELAY + OWN
ROBOT, STATION = ROLES = ("robot", "station")


def tls_entries(ca: str, cert: str, key: str) -> dict[str, Any]:
    """Zenoh configuration entries for mutually authenticated TLS links (file paths)."""
    tls = {
        "root_ca_certificate": ca,
        "listen_certificate": cert,
        "listen_private_key": key,
        "connect_certificate": cert,
        "connect_private_key": key,
        "enable_mtls": True,
        # Kept on: without it the connecting side would take any publicly trusted server.
        "verify_name_on_connect": True,
    }
    return {"transport/link/tls": tls, "transport/link/protocols": ["tls"]}


def acl(fleet: str, roster: Mapping[str, str]) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for ``roster`` (member name → role, revoked members
    left out)."""
    space = f"{PREFIX}/{fleet}"
    rules: list[dict[str, Any]] = [
        _rule("out", "egress", ["**"], EVERYTHING),
        _rule("read", "ingress", [f"{space}/**"], READ),
        _rule("relay", "ingress", [f"{space}/**"], RELAY),
    ]
    subjects: list[dict[str, Any]] = [{"id": "anyone"}]
    policies = [{"rules": ["out"], "subjects": ["anyone"]}]
    robots = sorted(n for n, role in roster.items() if role == ROBOT)
    for name, role in sorted(roster.items()):
        if role not in ROLES:
            raise ValueError(f"member {name!r}: role must be one of {ROLES}, not {role!r}")
        subjects.append({"id": f"m_{name}", "cert_common_names": [name]})
    if roster:
        policies.append({"rules": ["read"], "subjects": [f"m_{n}" for n in sorted(roster)]})
    if robots:
        policies.append({"rules": ["relay"], "subjects": [f"m_{n}" for n in robots]})
    for name in robots:
        own = [f"{space}/{name}", f"{space}/{name}/**"]  # its liveliness token, its messages
        rules.append(_rule(f"own_{name}", "ingress", own, OWN))
        policies.append({"rules": [f"own_{name}"], "subjects": [f"m_{name}"]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def _rule(rule_id: str, flow: str, keys: list[str], messages: list[str]) -> dict[str, Any]:
    return {
        "id": rule_id,
        "flows": [flow],
        "permission": "allow",
        "key_exprs": keys,
        "messages": messages,
    }


def secured(config: Config, credentials: Path) -> Config:
    """``config`` for the member whose folder is ``credentials``: its TLS endpoints in place of
    TCP ones (a relay in between carries TLS as it carries TCP)."""

    def tls(endpoints):
        return None if endpoints is None else tuple(e.replace("tcp/", "tls/", 1) for e in endpoints)

    t = config.transport
    transport = replace(t, listen=tls(t.listen), connect=tls(t.connect))
    security = replace(config.security, credentials=str(credentials))
    return replace(config, transport=transport, security=security)


def issue_fleet(folder: Path, fleet: str, robots: list[str]) -> dict[str, Path]:
    """A new fleet authority in ``folder`` with one member folder per robot (``gmmap demo
    --secure``, tests): robot name → its folder."""
    from gmmap.fleet.security.credentials import add_member, init_fleet

    init_fleet(folder, fleet)
    return {name: add_member(folder, name) for name in robots}
