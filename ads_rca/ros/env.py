"""The environment every ROS process we start runs in: local-only discovery, its own domain.

These machines must send no DDS traffic off the host, and parallel runs must not see each
other. So every child ROS process gets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (always,
whatever the caller's environment says), an explicit ``ROS_DOMAIN_ID`` and a ``ROS_LOG_DIR``.
Pure Python: no rclpy import.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping

#: Highest ROS_DOMAIN_ID that is safe on every platform (ports stay below 65535).
MAX_DOMAIN_ID = 101


def pick_domain_id(token: int | None = None) -> int:
    """A domain id in 1..MAX_DOMAIN_ID derived from ``token`` (default: this process id).

    Domain 0 (the ROS default) is avoided so a run never joins a stray default graph.
    """
    value = os.getpid() if token is None else token
    return 1 + value % MAX_DOMAIN_ID


def ros_environment(
    domain_id: int | None = None,
    log_dir: str | os.PathLike[str] | None = None,
    base: Mapping[str, str] | None = None,
) -> dict[str, str]:
    """A copy of ``base`` (default ``os.environ``) made safe for a child ROS process.

    ``domain_id`` None keeps the base's ROS_DOMAIN_ID when set, else picks one;
    ``log_dir`` None keeps the base's ROS_LOG_DIR when set, else a fresh temp folder.
    """
    env = dict(os.environ if base is None else base)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_STATIC_PEERS", None)
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(_checked_domain(domain_id))
    elif not env.get("ROS_DOMAIN_ID"):
        env["ROS_DOMAIN_ID"] = str(pick_domain_id())
    if log_dir is not None:
        env["ROS_LOG_DIR"] = os.fspath(log_dir)
    elif not env.get("ROS_LOG_DIR"):
        env["ROS_LOG_DIR"] = tempfile.mkdtemp(prefix="ads_rca_ros_log_")
    env["PYTHONUNBUFFERED"] = "1"
    # A crash in native code (DDS, rcl) then prints the Python stack instead of nothing.
    env["PYTHONFAULTHANDLER"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    return env


def apply_to_current_process(domain_id: int | None = None) -> dict[str, str]:
    """Make this process's own environment safe before it calls ``rclpy.init``."""
    env = ros_environment(domain_id)
    for key in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID", "ROS_LOG_DIR"):
        os.environ[key] = env[key]
    os.environ.pop("ROS_STATIC_PEERS", None)
    return env


def _checked_domain(domain_id: int) -> int:
    if not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise ValueError(f"ROS_DOMAIN_ID must be in 0..{MAX_DOMAIN_ID}, got {domain_id}")
    return domain_id


#: Fast DDS writers acknowledge only on a heartbeat, every 3 s by default, which would make
#: ``wait_for_all_acked`` (rate 0, exit_on_end) wait seconds per frame. This default data-writer
#: profile heartbeats every 1 ms instead (only while samples are unacknowledged); ROS QoS
#: still overrides everything else.
FAST_ACK_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <data_writer profile_name="ads_rca_fast_ack" is_default_profile="true">
      <times>
        <heartbeat_period><sec>0</sec><nanosec>1000000</nanosec></heartbeat_period>
      </times>
    </data_writer>
  </profiles>
</dds>
"""
PROFILES_VARIABLE = "FASTDDS_DEFAULT_PROFILES_FILE"


def use_fast_ack_profile() -> str | None:
    """Point this process's Fast DDS at :data:`FAST_ACK_PROFILE` (before ``rclpy.init``).

    A profiles file the user chose is kept (returns None); otherwise the file is written
    once to the temp folder and its path returned.
    """
    if os.environ.get(PROFILES_VARIABLE) or os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE"):
        return None
    path = os.path.join(tempfile.gettempdir(), f"ads_rca_fastdds_fast_ack_{os.getuid()}.xml")
    try:
        with open(path, encoding="utf-8") as existing:
            current = existing.read()
    except OSError:
        current = ""
    if current != FAST_ACK_PROFILE:
        partial = f"{path}.{os.getpid()}"
        with open(partial, "w", encoding="utf-8") as out:
            out.write(FAST_ACK_PROFILE)
        os.replace(partial, path)
    os.environ[PROFILES_VARIABLE] = path
    return path
