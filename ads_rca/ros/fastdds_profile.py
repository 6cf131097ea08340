"""The Fast DDS profiles file every ROS process we start reads, written where nobody else can.

Two things need it. Writers acknowledge only on a heartbeat (every 3 s by default), which
would make the player's ``wait_for_all_acked`` (rate 0) wait seconds per frame, so the
default data-writer profile heartbeats every 1 ms (only while samples are unacknowledged;
ROS QoS still overrides everything else). And under the loopback-only network rule the
participant's UDP transport is restricted to 127.0.0.1, so no port a participant receives
on is bound to 0.0.0.0 or another interface (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
alone keeps discovery local but still listens on every interface).

The file goes into a fresh private directory (``mkdtemp``: mode 0700, unpredictable name;
under ``XDG_RUNTIME_DIR`` when that is ours and 0700, else the temp folder), is created with
``O_EXCL | O_NOFOLLOW`` and is removed with its directory when this process exits. A fixed
name in a shared temp folder would let another user block the player or, through a planted
symlink, make it overwrite a file. Pure Python: no rclpy import.
"""

from __future__ import annotations

import atexit
import os
import shutil
import stat
import tempfile
from collections.abc import Mapping

#: The variable Fast DDS 3 reads its default profiles file from.
PROFILES_VARIABLE = "FASTDDS_DEFAULT_PROFILES_FILE"

#: Default data-writer profile: heartbeat every 1 ms while samples are unacknowledged.
_FAST_ACK = """    <data_writer profile_name="ads_rca_fast_ack" is_default_profile="true">
      <times>
        <heartbeat_period><sec>0</sec><nanosec>1000000</nanosec></heartbeat_period>
      </times>
    </data_writer>
"""

#: Default participant profile: UDP on 127.0.0.1 only. ``maxInitialPeersRange`` 32 is what
#: rmw_fastrtps gives its own LOCALHOST transport (how many participants per host are probed).
_LOOPBACK = """    <transport_descriptors>
      <transport_descriptor>
        <transport_id>ads_rca_udp_loopback</transport_id>
        <type>UDPv4</type>
        <maxInitialPeersRange>32</maxInitialPeersRange>
        <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="ads_rca_loopback" is_default_profile="true">
      <rtps>
        <builtin>
          <metatrafficUnicastLocatorList>
            <locator><udpv4><address>127.0.0.1</address></udpv4></locator>
          </metatrafficUnicastLocatorList>
          <initialPeersList>
            <locator><udpv4><address>127.0.0.1</address></udpv4></locator>
          </initialPeersList>
        </builtin>
        <defaultUnicastLocatorList>
          <locator><udpv4><address>127.0.0.1</address></udpv4></locator>
        </defaultUnicastLocatorList>
        <userTransports><transport_id>ads_rca_udp_loopback</transport_id></userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
      </rtps>
    </participant>
"""


def profile_xml(loopback_only: bool) -> str:
    """The profiles document: the fast-ack writer profile, plus the loopback participant."""
    body = (_LOOPBACK if loopback_only else "") + _FAST_ACK
    return (
        '<?xml version="1.0" encoding="UTF-8" ?>\n'
        '<dds xmlns="http://www.eprosima.com">\n'
        f"  <profiles>\n{body}  </profiles>\n</dds>\n"
    )


_written: dict[bool, str] = {}
_directory: list[str] = []


def profile_file(loopback_only: bool) -> str:
    """Path of :func:`profile_xml` written once per process in its private directory."""
    if loopback_only not in _written:
        name = "loopback.xml" if loopback_only else "fast_ack.xml"
        path = os.path.join(_private_directory(), name)
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
        fd = os.open(path, flags, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as out:
            out.write(profile_xml(loopback_only))
        _written[loopback_only] = path
    return _written[loopback_only]


def private_parent(environ: Mapping[str, str] | None = None) -> str:
    """``XDG_RUNTIME_DIR`` when it is a real directory of ours with mode 0700, else the temp
    folder (``mkdtemp`` below it makes the private directory either way)."""
    runtime = (os.environ if environ is None else environ).get("XDG_RUNTIME_DIR", "")
    if runtime and os.path.isabs(runtime):
        try:
            info = os.lstat(runtime)
        except OSError:
            info = None
        if (
            info is not None
            and stat.S_ISDIR(info.st_mode)
            and info.st_uid == os.getuid()
            and stat.S_IMODE(info.st_mode) & 0o077 == 0
        ):
            return runtime
    return tempfile.gettempdir()


def _private_directory() -> str:
    if not _directory:
        path = tempfile.mkdtemp(prefix="ads_rca_fastdds_", dir=private_parent())
        _directory.append(path)
        atexit.register(_remove_directory)
    return _directory[0]


def _remove_directory() -> None:
    """At exit: the profiles are read once, when each participant is created."""
    if _directory:
        shutil.rmtree(_directory.pop(), ignore_errors=True)
        _written.clear()
