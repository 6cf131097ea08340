"""``batch --scheduler tcp://HOST:PORT`` checked before distributed is given the address.

Pointed at something that is no Dask scheduler, distributed's client fails badly: its TCP
comm reads an 8-byte length first and allocates a buffer of that length at once
(``comm/tcp.py``: ``read_bytes_rw`` → ``host_array(n)``), so an HTTP server's reply
``HTTP/1.1`` becomes a request for 3.07 EiB (a traceback; a smaller absurd length would
really be allocated); and its ``connect`` awaits the peer's handshake with no timeout, so a
peer that accepts and stays silent hangs it for ever, past the connect timeout.

So :func:`check_scheduler` first talks to the address itself, as distributed's ``connect``
does, within :data:`TIMEOUT` seconds in all: a TCP connection; our handshake sent, the
same bytes distributed sends (an HTTP server answers them at once with an error, where it
would wait for a request in silence); the peer's handshake read, which a Dask listener
sends unasked on every new connection (``Comm.on_connection`` writes it before reading).
Its framing (``comm/tcp.py``, ``protocol/utils.py``): an 8-byte length L (native order),
then L bytes holding a frame count N, N 8-byte frame lengths and the frames, the first a
msgpack map (about 60 bytes in all). A length over :data:`MAX_HANDSHAKE_BYTES`, a count or
frame lengths that do not add up to L, a first frame that is no msgpack map, silence or a
closed connection are refused in one line; at most 8 + :data:`MAX_HANDSHAKE_BYTES` bytes
are read, whatever the peer says. Only then is the address handed to distributed.

Why a probe rather than distributed's connect under a wall-clock deadline (in a thread):
the allocation happens at once, well within any deadline, and a thread stuck in the
handshake cannot be stopped (the process could only end with it still running). The probe
costs one extra connection, closed once both handshakes are exchanged. A peer that does
speak Dask is trusted as distributed trusts it (it sends pickles: a scheduler can run code
in this process); ``--scheduler`` is the user's choice. Only ``tcp://`` is probed:
``tls://`` needs the cluster's certificates and the other schemes frame differently, so
those addresses go to distributed unchecked.
"""

from __future__ import annotations

import pickle
import socket
import struct
import sys
import time

from ads_rca.errors import InputError
from ads_rca.foundation.text import printable

#: Seconds for the whole check: connecting and reading the handshake.
TIMEOUT = 15.0
#: The largest handshake accepted (a real one is about 60 bytes).
MAX_HANDSHAKE_BYTES = 64 * 1024
#: Frames accepted in a handshake (a real one has 1).
MAX_FRAMES = 16
_U64 = struct.Struct("Q")  # as distributed packs it: native order
#: First bytes of a msgpack map: fixmap, map16, map32.
_MSGPACK_MAP = frozenset(range(0x80, 0x90)) | {0xDE, 0xDF}


def check_scheduler(address: str, timeout: float = TIMEOUT) -> None:
    """:class:`InputError` unless ``address`` (``tcp://HOST:PORT``) answers with a Dask
    handshake within ``timeout`` seconds (other schemes: not checked)."""
    if not address.startswith("tcp://"):
        return
    host, port = _host_port(address)
    deadline = time.monotonic() + timeout
    where = f"--scheduler {printable(address)}"
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except TimeoutError:
        raise InputError(f"{where}: cannot connect (no answer within {timeout:g} s)") from None
    except OSError as error:
        raise InputError(f"{where}: cannot connect ({error.strerror or error})") from None
    with sock:
        try:
            sock.sendall(_HANDSHAKE)
            header = _read(sock, _U64.size, deadline)
            (length,) = _U64.unpack(header)
            if length > MAX_HANDSHAKE_BYTES:
                raise _NotDask(f"its answer began with {_shown(header)}")
            _check_frames(_read(sock, length, deadline), header)
        except TimeoutError:
            raise InputError(
                f"{where}: not a Dask scheduler (no handshake within {timeout:g} s)"
            ) from None
        except _NotDask as error:
            raise InputError(f"{where}: not a Dask scheduler ({error})") from None
        except OSError as error:
            raise InputError(f"{where}: cannot connect ({error.strerror or error})") from None


class _NotDask(InputError):
    """What the peer sent is no Dask handshake (the message says how); caught here and
    said as one line naming the address."""


def _handshake() -> bytes:
    """What distributed's client sends first on a connection to the same host: the
    msgpack map ``{"compression": None, "python": (major, minor, micro),
    "pickle-protocol": N}`` as one frame (a count, its length, the frame), the message's
    length before it."""
    version = bytes([0x93, *(v & 0x7F for v in sys.version_info[:3])])  # 3 positive fixints
    frame = (
        b"\x83"  # a map of 3
        + b"\xabcompression\xc0"  # nil
        + b"\xa6python"
        + version
        + b"\xafpickle-protocol"
        + bytes([pickle.HIGHEST_PROTOCOL])
    )
    message = _U64.pack(1) + _U64.pack(len(frame)) + frame
    return _U64.pack(len(message)) + message


def _host_port(address: str) -> tuple[str, int]:
    """HOST and PORT of ``tcp://HOST:PORT`` (``[v6]:PORT`` too)."""
    rest = address[len("tcp://") :]
    host, sep, port = rest.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(
            f"--scheduler {printable(address)}: expected an address like tcp://host:8786"
        )
    return host, int(port)


def _read(sock: socket.socket, size: int, deadline: float) -> bytes:
    """Exactly ``size`` bytes, before ``deadline`` (else TimeoutError)."""
    parts: list[bytes] = []
    left = size
    while left:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError
        sock.settimeout(remaining)
        chunk = sock.recv(min(left, 1 << 16))
        if not chunk:
            got = b"".join(parts)
            said = f", after {_shown(got)}" if got else ""
            raise _NotDask(f"it closed the connection without a Dask handshake{said}")
        parts.append(chunk)
        left -= len(chunk)
    return b"".join(parts)


def _check_frames(body: bytes, header: bytes) -> None:
    """``body`` is a Dask message: a frame count, the frame lengths adding up, and a first
    frame that is a msgpack map."""
    wrong = _NotDask(f"its answer began with {_shown(header + body)}")
    if len(body) < _U64.size:
        raise wrong
    (frames,) = _U64.unpack_from(body)
    start = _U64.size * (1 + frames)
    if not 0 < frames <= MAX_FRAMES or start > len(body):
        raise wrong
    lengths = struct.unpack_from(f"{frames}Q", body, _U64.size)
    if start + sum(lengths) != len(body) or lengths[0] == 0 or body[start] not in _MSGPACK_MAP:
        raise wrong


def _shown(data: bytes) -> str:
    """The first bytes a peer sent, as a short escaped text."""
    return printable(repr(data[:16]) + ("..." if len(data) > 16 else ""))


_HANDSHAKE = _handshake()
