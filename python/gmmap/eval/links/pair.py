"""Two robots' transports joined by one counting relay (`relayed_pair`), for tests and benchmarks
of what one link carries."""

from __future__ import annotations

import contextlib

from gmmap.eval.links.datagrams import relay_for
from gmmap.eval.links.relay import ZENOH_NO_GOSSIP


@contextlib.contextmanager
def relayed_pair(fleet: str = "pair", timeout: float = 10.0, protocol: str = "tcp"):
    """Two robots' transports, ``a`` listening and ``b`` reaching it only through a counting
    relay for ``protocol`` (`relay_for`; gossip off), once each sees the other: yields
    (relay, a, b). For tests and benchmarks of what one link carries."""
    from gmmap.errors import TransportError  # lazily: Zenoh loads with the transport
    from gmmap.fleet.net.keys import free_port
    from gmmap.fleet.net.transport import Transport, TransportConfig
    from gmmap.options import TransportOptions

    port = free_port()
    with relay_for(protocol)(("127.0.0.1", port)) as relay:
        common = dict(protocol=protocol, zenoh_options=ZENOH_NO_GOSSIP)
        a_opts = TransportOptions(port=port, **common)
        b_opts = TransportOptions(connect=(relay.endpoint,), **common)
        with (
            Transport(TransportConfig(fleet, "a", a_opts)) as a,
            Transport(TransportConfig(fleet, "b", b_opts)) as b,
        ):
            if not (b.wait_for_peers(["a"], timeout) and a.wait_for_peers(["b"], timeout)):
                raise TransportError("the two robots did not meet through the relay")
            yield relay, a, b
