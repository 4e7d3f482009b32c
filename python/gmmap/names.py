"""Robot, fleet and kind names and Zenoh endpoints: what the configuration and the transport
accept, checked before anything reaches Zenoh."""

from __future__ import annotations

import ipaddress
import re

from gmmap.errors import TransportConfigError

# Names become one key-expression chunk each: verbatim characters only ('?', '#', '@'), nothing
# that needs escaping. Leading letter or digit.
NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}")
PREFIX = "gmmap"  # every key expression's first chunk: gmmap/<fleet>/… (`gmmap.fleet.net.keys`)
_IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
_OTHER_PROTOCOLS = ("unixsock-stream", "unixpipe", "serial", "vsock")
MODES = ("peer", "client")


def check_name(what: str, name: object, error: type[Exception] = TransportConfigError) -> str:
    if not isinstance(name, str) or not NAME_RE.fullmatch(name):
        raise error(
            f"{what} must be 1-64 characters from [A-Za-z0-9_.-] starting with a letter or digit "
            f"(no '/', '*', '?', '#', '@', '$' or spaces); got {name!r}"
        )
    return name


def check_endpoint(endpoint: object, *, listen: bool) -> str:
    """A Zenoh endpoint ``<protocol>/<address>[?metadata][#config]``; IP addresses need a port."""
    if not isinstance(endpoint, str) or not endpoint or endpoint != endpoint.strip():
        raise TransportConfigError(f"endpoint must be a non-empty string; got {endpoint!r}")
    locator = re.split(r"[?#]", endpoint, maxsplit=1)[0]
    protocol, sep, address = locator.partition("/")
    if not sep or not address:
        raise TransportConfigError(
            f"endpoint {endpoint!r} is not <protocol>/<address> (e.g. tcp/127.0.0.1:7447)"
        )
    if protocol in _OTHER_PROTOCOLS:
        return endpoint
    if protocol not in _IP_PROTOCOLS:
        raise TransportConfigError(
            f"endpoint {endpoint!r}: unknown protocol {protocol!r} "
            f"(one of {', '.join(_IP_PROTOCOLS + _OTHER_PROTOCOLS)})"
        )
    host, sep, port_text = address.rpartition(":")
    if not sep or not host or not port_text.isdigit():
        raise TransportConfigError(f"endpoint {endpoint!r}: address must be <host>:<port>")
    port = int(port_text)
    if not 0 <= port <= 65535 or (port == 0 and not listen):
        raise TransportConfigError(f"endpoint {endpoint!r}: port {port} out of range")
    if host.startswith("["):
        if not host.endswith("]"):
            raise TransportConfigError(f"endpoint {endpoint!r}: unbalanced '[' in IPv6 address")
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError as err:
            raise TransportConfigError(f"endpoint {endpoint!r}: {err}") from None
    elif not re.fullmatch(r"[A-Za-z0-9.\-]+", host):
        raise TransportConfigError(f"endpoint {endpoint!r}: bad host {host!r}")
    return endpoint
