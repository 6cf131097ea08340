"""The Zenoh session configuration: loopback-only unless the user says otherwise.

Zenoh's default scouts by multicast and listens on every interface. Nothing here may leave
the machine by accident, so every configuration this project builds sets the mode, turns
multicast and gossip scouting off and names its endpoints; an endpoint on another interface
is refused unless ``allow_remote`` is given (docs: Zenoh's own TLS and access control are
the way to expose it).
"""

from __future__ import annotations

import errno
import ipaddress
import json
import re
import socket
from collections.abc import Sequence
from dataclasses import dataclass

from ads_rca.errors import ConfigError

MODES = ("peer", "client")
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+):(\d{1,5})$")


@dataclass(frozen=True)
class Endpoint:
    protocol: str
    host: str
    port: int

    def __str__(self) -> str:
        return f"{self.protocol}/{self.host}:{self.port}"

    @property
    def loopback(self) -> bool:
        host = self.host.strip("[]")
        if host == "localhost":
            return True
        try:
            return ipaddress.ip_address(host).is_loopback
        except ValueError:
            return False


def parse_endpoint(text: str, what: str) -> Endpoint:
    """``proto/host:port`` (tcp, udp, tls, quic; port 1–65535), refused in one line."""
    found = _ENDPOINT.match(text.strip())
    shown = text.encode("unicode_escape").decode("ascii")[:80]
    if not found:
        raise ConfigError(f"{what}: {shown!r} is not PROTOCOL/HOST:PORT (e.g. {DEFAULT_ENDPOINT})")
    port = int(found.group(3))
    if not 1 <= port <= 65535:
        raise ConfigError(f"{what}: port {port} is out of range [1, 65535]")
    return Endpoint(found.group(1), found.group(2), port)


def check_listen_free(listen: Sequence[str], option: str) -> None:
    """ConfigError (one line) when a TCP endpoint to listen on is taken, checked by binding
    it a moment: a peer that cannot listen fails in its own process later, after the graph
    began (another replay's bridge holds the default port). ``option``: what to give to
    listen elsewhere, as the front end spells it. A race with a later taker stays possible."""
    for text in listen:
        endpoint = parse_endpoint(text, "zenoh listen endpoint")
        if endpoint.protocol != "tcp":
            continue
        host = endpoint.host.strip("[]")
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            try:
                probe.bind((host, endpoint.port))
            except OSError as error:
                reason = "in use" if error.errno == errno.EADDRINUSE else error.strerror
                raise ConfigError(
                    f"zenoh listen endpoint {endpoint}: {reason} (another bridge or Zenoh "
                    f"router?); give {option} with a free port"
                ) from None


def session_config(
    mode: str = "peer",
    listen: Sequence[str] = (DEFAULT_ENDPOINT,),
    connect: Sequence[str] = (),
    allow_remote: bool = False,
    allow_option: str = "--allow-remote",
) -> str:
    """The JSON5 text of a Zenoh config: ``mode``, the listen and connect endpoints,
    multicast and gossip scouting off. Non-loopback endpoints need ``allow_remote``, which
    the refusal names as the user gives it (``allow_option``: the front end's option)."""
    if mode not in MODES:
        raise ConfigError(f"zenoh mode: {mode[:40]!r} is not one of {', '.join(MODES)}")
    listened = [parse_endpoint(e, "zenoh listen endpoint") for e in listen]
    connected = [parse_endpoint(e, "zenoh connect endpoint") for e in connect]
    if mode == "client" and not connected:
        raise ConfigError("zenoh mode client: give at least one connect endpoint")
    if not allow_remote:
        for endpoint in (*listened, *connected):
            if not endpoint.loopback:
                raise ConfigError(
                    f"zenoh endpoint {endpoint}: not on loopback; give {allow_option} to use "
                    "another interface (and configure Zenoh's TLS and access control)"
                )
    config = {
        "mode": mode,
        "listen": {"endpoints": [str(e) for e in listened] if mode == "peer" else []},
        "connect": {"endpoints": [str(e) for e in connected]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
    }
    return json.dumps(config)
