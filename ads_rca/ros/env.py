"""The environment every ROS process we start runs in: local-only discovery, its own domain.

These machines must send no DDS traffic off the host, and parallel runs must not see each
other. So every child ROS process gets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (always,
whatever the caller's environment says), an explicit ``ROS_DOMAIN_ID``, a ``ROS_LOG_DIR``,
and a Fast DDS profile binding its UDP transport to 127.0.0.1 (:mod:`ads_rca.ros.fastdds_profile`).
Variables that could send discovery or data elsewhere (:data:`REDIRECTING_VARIABLES`: a
discovery server, static peers, another RMW, the user's own profiles) are removed unless
the user opts in (``--allow-external-discovery`` or ``ADS_RCA_ALLOW_EXTERNAL_DISCOVERY=1``);
a node started by hand keeps its environment but says which of them it found.
Pure Python: no rclpy import.
"""

from __future__ import annotations

import importlib.metadata
import os
import tempfile
from collections.abc import Mapping, MutableMapping

from ads_rca.errors import InputError
from ads_rca.ros.fastdds_profile import PROFILES_VARIABLE, profile_file

#: Highest ROS_DOMAIN_ID we pick by ourselves: ROS's safe range on Linux (above it, the
#: ports of several participants can fall into the kernel's ephemeral range).
MAX_DOMAIN_ID = 101
#: Highest ROS_DOMAIN_ID accepted when the user gives one: Fast DDS's port formula
#: (7400 + 250 * domain + offsets) leaves the 16-bit port range above it.
MAX_VALID_DOMAIN_ID = 232

#: ``1``: keep the caller's discovery and transport settings (:data:`REDIRECTING_VARIABLES`).
ALLOW_EXTERNAL_VARIABLE = "ADS_RCA_ALLOW_EXTERNAL_DISCOVERY"
#: Set beside :data:`PROFILES_VARIABLE` when the profile is ours (a node does not warn about it).
OWN_PROFILE_VARIABLE = "ADS_RCA_FASTDDS_PROFILE"
#: Fast DDS loads ``DEFAULT_FASTDDS_PROFILES.xml`` from the working directory unless this is 1.
SKIP_CWD_PROFILE_VARIABLE = "SKIP_DEFAULT_XML_FILE"
CWD_PROFILE = "DEFAULT_FASTDDS_PROFILES.xml"

#: Variables that can send DDS discovery or data to another machine, or hand the transports
#: to a configuration we did not write: Fast DDS's discovery server / easy mode (and the
#: file it re-reads them from), rmw's static peers, the user's profiles files and builtin
#: transport choice, and other RMWs (whose own discovery our profile does not restrict).
REDIRECTING_VARIABLES = (
    "ROS_DISCOVERY_SERVER",
    "ROS_SUPER_CLIENT",
    "ROS2_EASY_MODE",
    "ROS_STATIC_PEERS",
    "FASTDDS_ENVIRONMENT_FILE",
    PROFILES_VARIABLE,
    "FASTRTPS_DEFAULT_PROFILES_FILE",
    "FASTDDS_BUILTIN_TRANSPORTS",
    "RMW_IMPLEMENTATION",
    "CYCLONEDDS_URI",
    "NDDS_DISCOVERY_PEERS",
    "NDDS_QOS_PROFILES",
)
#: Every variable with one of these prefixes configures rmw_zenoh / Zenoh sessions.
REDIRECTING_PREFIXES = ("ZENOH_", "RMW_ZENOH_")
#: RMW_IMPLEMENTATION values that are Fast DDS (what our profile configures).
FASTDDS_RMWS = ("rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")


def pick_domain_id(token: int | None = None) -> int:
    """A domain id in 1..MAX_DOMAIN_ID derived from ``token`` (default: this process id).

    Domain 0 (the ROS default) is avoided so a run never joins a stray default graph.
    """
    value = os.getpid() if token is None else token
    return 1 + value % MAX_DOMAIN_ID


def parse_domain_id(text: str, source: str) -> int:
    """``text`` as a ROS domain id (0..MAX_VALID_DOMAIN_ID), or InputError naming ``source``.

    Plain decimal only: rcl reads ``010`` as octal 8 and ``-1`` as "the default" (0)."""
    canonical = text.isascii() and text.isdigit() and str(int(text)) == text
    if canonical and int(text) <= MAX_VALID_DOMAIN_ID:
        return int(text)
    raise InputError(
        f"{source} must be a ROS domain id, an integer in 0..{MAX_VALID_DOMAIN_ID}, got {text!r}"
    )


def requested_domain_id(flag: str | None, environ: Mapping[str, str] | None = None) -> int | None:
    """The domain the user asked for: ``--domain-id``, else a non-empty ``ROS_DOMAIN_ID``
    (empty means unset, as in rcl); None when neither is given (pick one). Bad values raise
    InputError (one line)."""
    if flag is not None:
        return parse_domain_id(flag, "--domain-id")
    value = (os.environ if environ is None else environ).get("ROS_DOMAIN_ID", "")
    return parse_domain_id(value, "ROS_DOMAIN_ID") if value else None


def domain_id_problem(environ: Mapping[str, str] | None = None) -> str | None:
    """Why this process's ``ROS_DOMAIN_ID`` cannot be used (None: unset, empty or valid).

    rcl would otherwise fail with a traceback (``abc``), fall back to domain 0 (``-1``) or
    let Fast DDS compute ports past 65535 (``999``)."""
    try:
        requested_domain_id(None, environ)
    except InputError as error:
        return str(error)
    return None


def redirecting_variables(environ: Mapping[str, str]) -> list[str]:
    """Names of the variables in ``environ`` that :func:`ros_environment` removes."""
    return [
        name
        for name in sorted(environ)
        if name in REDIRECTING_VARIABLES or name.startswith(REDIRECTING_PREFIXES)
    ]


def external_discovery_allowed(environ: Mapping[str, str]) -> bool:
    return environ.get(ALLOW_EXTERNAL_VARIABLE, "") == "1"


def discovery_note(env: Mapping[str, str]) -> str:
    """How a command describes the discovery of the environment it made."""
    if external_discovery_allowed(env):
        return "discovery LOCALHOST, external discovery settings kept"
    return "discovery LOCALHOST"


def ros_environment(
    domain_id: int | None = None,
    log_dir: str | os.PathLike[str] | None = None,
    base: Mapping[str, str] | None = None,
    allow_external: bool | None = None,
) -> dict[str, str]:
    """A copy of ``base`` (default ``os.environ``) made safe for a child ROS process.

    ``domain_id`` None keeps the base's ROS_DOMAIN_ID when set (InputError if it is no
    domain id), else picks one; ``log_dir`` None keeps the base's ROS_LOG_DIR when set, else
    a fresh temp folder. ``allow_external`` (None: the base's ``ADS_RCA_ALLOW_EXTERNAL_DISCOVERY``)
    keeps the redirecting variables and the user's own profiles file.
    """
    env = dict(os.environ if base is None else base)
    allow = external_discovery_allowed(env) if allow_external is None else allow_external
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(_checked_domain(domain_id))
    else:
        requested = requested_domain_id(None, env)
        env["ROS_DOMAIN_ID"] = str(pick_domain_id() if requested is None else requested)
    if log_dir is not None:
        env["ROS_LOG_DIR"] = os.fspath(log_dir)
    elif not env.get("ROS_LOG_DIR"):
        env["ROS_LOG_DIR"] = tempfile.mkdtemp(prefix="ads_rca_ros_log_")
    _apply_network_rule(env, allow)
    env["PYTHONUNBUFFERED"] = "1"
    # A crash in native code (DDS, rcl) then prints the Python stack instead of nothing.
    env["PYTHONFAULTHANDLER"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    return env


def _apply_network_rule(env: MutableMapping[str, str], allow: bool) -> None:
    """Clear what could redirect discovery (unless ``allow``) and point Fast DDS at our profile.

    Opted in, the user's own profiles file wins (ours only adds the fast-ack writers, with no
    transport restriction: the user asked for discovery beyond this machine)."""
    if allow:
        env[ALLOW_EXTERNAL_VARIABLE] = "1"
        if env.get(PROFILES_VARIABLE) and env.get(OWN_PROFILE_VARIABLE) != env[PROFILES_VARIABLE]:
            env.pop(OWN_PROFILE_VARIABLE, None)
            return
    else:
        for name in redirecting_variables(env):
            del env[name]
        env.pop(ALLOW_EXTERNAL_VARIABLE, None)
        env[SKIP_CWD_PROFILE_VARIABLE] = "1"
    path = profile_file(loopback_only=not allow)
    env[PROFILES_VARIABLE] = path
    env[OWN_PROFILE_VARIABLE] = path


def apply_to_current_process(domain_id: int | None = None) -> dict[str, str]:
    """Make this process's own environment safe before it calls ``rclpy.init``."""
    env = ros_environment(domain_id)
    for key in [k for k in os.environ if k not in env]:
        del os.environ[key]
    os.environ.update(env)
    return env


def _checked_domain(domain_id: int) -> int:
    if not 0 <= domain_id <= MAX_VALID_DOMAIN_ID:
        raise ValueError(f"ROS_DOMAIN_ID must be in 0..{MAX_VALID_DOMAIN_ID}, got {domain_id}")
    return domain_id


def node_warnings(environ: Mapping[str, str], cwd: str | None = None) -> list[str]:
    """What a node started by hand should say about its environment (one line each).

    The launcher clears these variables; a node started by ``ros2 run`` or a console script
    keeps them (its user chose them) but names each, so nobody is surprised that discovery
    left the machine. Values are not repeated (a profiles path or peer list may be private).
    With ``ADS_RCA_ALLOW_EXTERNAL_DISCOVERY=1`` the user opted in: nothing to say."""
    if external_discovery_allowed(environ):
        return []
    found = [
        name
        for name in redirecting_variables(environ)
        if not (name == "RMW_IMPLEMENTATION" and environ[name] in FASTDDS_RMWS)
        and not (name == PROFILES_VARIABLE and environ[name] == environ.get(OWN_PROFILE_VARIABLE))
    ]
    lines = [
        f"{name} is set: DDS discovery or transports may reach beyond this machine "
        f"(ads-rca replay/demo clear it; set {ALLOW_EXTERNAL_VARIABLE}=1 to silence this)"
        for name in found
    ]
    directory = os.getcwd() if cwd is None else cwd
    if environ.get(SKIP_CWD_PROFILE_VARIABLE) != "1" and os.path.isfile(
        os.path.join(directory, CWD_PROFILE)
    ):
        lines.append(
            f"{CWD_PROFILE} in the working directory configures Fast DDS "
            f"(set {SKIP_CWD_PROFILE_VARIABLE}=1 to ignore it)"
        )
    return lines


def use_node_profile(environ: MutableMapping[str, str] | None = None) -> str | None:
    """Point this process's Fast DDS at our profile (before ``rclpy.init``) unless a profiles
    file is already chosen (the user's, or ours from the launcher): returns None then.

    The loopback participant is included when discovery is LOCALHOST (the network rule);
    a node started by hand for a wider range keeps every interface."""
    env = os.environ if environ is None else environ
    if env.get(PROFILES_VARIABLE) or env.get("FASTRTPS_DEFAULT_PROFILES_FILE"):
        return None
    loopback = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").upper() == "LOCALHOST"
    path = profile_file(loopback_only=loopback)
    env[PROFILES_VARIABLE] = path
    env[OWN_PROFILE_VARIABLE] = path
    return path


#: rclpy's major version → the released ROS 2 distribution that ships it (a rolling
#: install sets ROS_DISTRO).
RCLPY_DISTROS = {3: "humble", 4: "iron", 7: "jazzy", 9: "kilted"}


def ros_distro(environ: Mapping[str, str] | None = None) -> str:
    """The ROS 2 distribution this process runs on: ``ROS_DISTRO`` (set by a sourced ROS
    install, what rosbag2 itself records), else the one that released the installed rclpy
    (the PyPI wheels set no ``ROS_DISTRO``); '' when neither tells."""
    value = (os.environ if environ is None else environ).get("ROS_DISTRO", "").strip()
    if value:
        return value
    try:
        major = int(importlib.metadata.version("rclpy").split(".")[0])
    except (importlib.metadata.PackageNotFoundError, ValueError):
        return ""
    return RCLPY_DISTROS.get(major, "")
