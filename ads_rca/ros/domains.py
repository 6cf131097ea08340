"""Which ROS domain ids are in use on this machine, and a free one for a new graph.

Why: a graph that shares its domain with another sees its topics (``replay`` keeps to its
own run anyway, see :mod:`ads_rca.live.runid`, but a quiet domain also spares both sides the
discovery traffic). Under the loopback-only rule every participant we could meet runs on
this host, and every RTPS participant (Fast DDS, Cyclone DDS, Connext) binds the unicast
UDP ports of its domain's block, ``7400 + 250 * domain + 10 ...``: a domain whose block has
a bound port has a participant. Reading ``/proc/net/udp`` sees every user's sockets at
once, with no discovery wait. Not seen: participants in another network namespace, and
rmws that do not use RTPS ports (e.g. Zenoh). Pure Python: no rclpy import.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

#: RTPS port mapping (the DDS interoperability spec's defaults, used by every rmw here).
PORT_BASE = 7400
DOMAIN_GAIN = 250
#: Domain ids tried: 1..101 (0 is ROS's default graph; above 101 ports can collide with the
#: kernel's ephemeral range on Linux).
FIRST_DOMAIN = 1
LAST_DOMAIN = 101
_TABLES = (Path("/proc/net/udp"), Path("/proc/net/udp6"))


def bound_udp_ports(tables: Iterable[Path] = _TABLES) -> set[int]:
    """Local UDP ports bound on this host (this network namespace), any address, any user."""
    ports: set[int] = set()
    for table in tables:
        try:
            lines = table.read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) > 1 and ":" in fields[1]:
                ports.add(int(fields[1].rsplit(":", 1)[1], 16))
    return ports


def domains_in_use(ports: Iterable[int] | None = None) -> set[int]:
    """Domain ids with at least one participant on this host (by their RTPS ports)."""
    found = bound_udp_ports() if ports is None else ports
    return {
        (port - PORT_BASE) // DOMAIN_GAIN
        for port in found
        if port >= PORT_BASE and (port - PORT_BASE) % DOMAIN_GAIN >= 10
    }


def free_domain_id(start: int | None = None, in_use: set[int] | None = None) -> int | None:
    """A domain id in FIRST..LAST_DOMAIN with no participant, searching from ``start``
    (default: from this process id, so two runs started together seldom pick the same);
    None when every one is taken."""
    busy = domains_in_use() if in_use is None else in_use
    count = LAST_DOMAIN - FIRST_DOMAIN + 1
    offset = (os.getpid() if start is None else start - FIRST_DOMAIN) % count
    for step in range(count):
        domain = FIRST_DOMAIN + (offset + step) % count
        if domain not in busy:
            return domain
    return None
