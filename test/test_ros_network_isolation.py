"""Network isolation of every ROS process we start, tested on real processes and sockets.

Domain ids (any valid one accepted, bad ones refused in one line), variables that redirect
discovery (cleared by the launcher, named by a node started by hand, and proved silent on
the wire with a UDP socket standing in for a discovery server), the Fast DDS profile (in a
private directory, never through a planted symlink) and the sockets the nodes hold (every
port DDS receives on bound to 127.0.0.1).
"""

from __future__ import annotations

import json
import os
import socket
import stat
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from ads_rca.params import make_params
from ads_rca.ros.env import (
    OWN_PROFILE_VARIABLE,
    REDIRECTING_VARIABLES,
    ros_environment,
)
from ads_rca.ros.fastdds_profile import PROFILES_VARIABLE, private_parent, profile_file
from ads_rca.ros.graph import Graph, GraphSpec
from ads_rca.ros.launcher import Launcher, ManagedProcess, ParamValue, node_command

if TYPE_CHECKING:
    from conftest import RosEnv

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "cut_in_perception"
CLI = [sys.executable, "-m", "ads_rca.cli"]
PLAYER = "ads_rca.ros.player"


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


# --- domain ids ---------------------------------------------------------------------------


@pytest.mark.parametrize("value", ["233", "999", "-1", "abc", "", "010", "1e2"])
def test_bad_domain_id_flag_is_one_line_exit_2(ros_env: RosEnv, value: str) -> None:
    command = ManagedProcess("replay", [*CLI, "replay", str(EXAMPLE), "--domain-id", value])
    assert command.wait(60) == 2, command.output
    lines = _lines(command.output)
    assert "Traceback" not in command.output
    assert len(lines) == 1 and "--domain-id" in lines[0] and "0..232" in lines[0], lines


def test_domain_ids_above_101_are_accepted(ros_env: RosEnv, tmp_path: Path) -> None:
    """232 is Fast DDS's last domain: a real demo on it plays the whole log."""
    argv = [*CLI, "demo", str(EXAMPLE), "--domain-id", "232", "--out", str(tmp_path / "out")]
    demo = ManagedProcess("demo", argv, ros_env.env)
    assert demo.wait(120) == 0, demo.output
    assert "ROS_DOMAIN_ID=232" in demo.output and "complete" in demo.output


@pytest.mark.parametrize("value", ["abc", "-1", "999", "07"])
def test_hostile_ros_domain_id_in_the_environment(ros_env: RosEnv, value: str) -> None:
    """Commands refuse it in one line; a node logs one error and exits 2 (rcl would raise
    an RCLError traceback for "abc" and silently use domain 0 for "-1")."""
    env = {**ros_env.env, "ROS_DOMAIN_ID": value}
    command = ManagedProcess("demo", [*CLI, "demo", str(EXAMPLE), "--timeout", "20"], env)
    assert command.wait(60) == 2, command.output
    lines = _lines(command.output)
    assert len(lines) == 1 and "ROS_DOMAIN_ID" in lines[0] and repr(value) in lines[0], lines
    for module in (PLAYER, "ads_rca.ros.aggregator"):
        node = ManagedProcess(module, node_command(module, {"log_path": str(EXAMPLE)}), env)
        assert node.wait(60) == 2, node.output
        lines = _lines(node.output)
        assert "Traceback" not in node.output
        assert len(lines) == 1 and "ERROR" in lines[0] and "ROS_DOMAIN_ID" in lines[0], lines


def test_empty_ros_domain_id_means_unset_as_in_rcl(ros_env: RosEnv) -> None:
    env = ros_environment(log_dir=ros_env.log_dir, base={**ros_env.env, "ROS_DOMAIN_ID": ""})
    assert 1 <= int(env["ROS_DOMAIN_ID"]) <= 101


# --- variables that redirect discovery ----------------------------------------------------

HOSTILE = {
    "ROS_DISCOVERY_SERVER": "192.0.2.77:11811",
    "ROS_SUPER_CLIENT": "TRUE",
    "ROS2_EASY_MODE": "192.0.2.77",
    "ROS_STATIC_PEERS": "192.0.2.77",
    "FASTDDS_ENVIRONMENT_FILE": "/tmp/somebody_elses.json",
    "FASTDDS_BUILTIN_TRANSPORTS": "LARGE_DATA",
    "RMW_IMPLEMENTATION": "rmw_zenoh_cpp",
    "CYCLONEDDS_URI": "file:///tmp/cyclone.xml",
    "ZENOH_SESSION_CONFIG_URI": "/tmp/zenoh.json5",
    "RMW_ZENOH_CONFIG": "x",
}

PRINT_ENV = "import json, os; print(json.dumps(dict(os.environ)))"


def _child_environment(env: dict[str, str]) -> dict[str, str]:
    """The environment a real child started by the launcher sees."""
    with Launcher(env) as launcher:
        child = launcher.start("env", [sys.executable, "-c", PRINT_ENV])
        assert child.wait(30) == 0, child.output
    document: dict[str, str] = json.loads(child.output.splitlines()[-1])
    return document


def test_launcher_children_never_inherit_redirecting_variables(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    user_profile = tmp_path / "mine.xml"
    user_profile.write_text("<dds/>")
    base = {**ros_env.env, **HOSTILE, PROFILES_VARIABLE: str(user_profile)}
    base.pop(OWN_PROFILE_VARIABLE)
    child = _child_environment(ros_environment(ros_env.domain_id, ros_env.log_dir, base))
    assert not set(HOSTILE) & set(child)
    assert child[PROFILES_VARIABLE] != str(user_profile)
    assert child[PROFILES_VARIABLE] == child[OWN_PROFILE_VARIABLE]
    assert child["SKIP_DEFAULT_XML_FILE"] == "1"  # no DEFAULT_FASTDDS_PROFILES.xml from the cwd
    assert child["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"

    # Opted in (the flag, or the variable): everything is kept, the user's profile included.
    for opted in (
        ros_environment(ros_env.domain_id, ros_env.log_dir, base, allow_external=True),
        ros_environment(
            ros_env.domain_id,
            ros_env.log_dir,
            {**base, "ADS_RCA_ALLOW_EXTERNAL_DISCOVERY": "1"},
        ),
    ):
        child = _child_environment(opted)
        assert {name: child.get(name) for name in HOSTILE} == HOSTILE
        assert child[PROFILES_VARIABLE] == str(user_profile)
        assert child["ADS_RCA_ALLOW_EXTERNAL_DISCOVERY"] == "1"
    assert set(REDIRECTING_VARIABLES) >= set(HOSTILE) - {"ZENOH_SESSION_CONFIG_URI"} - {
        "RMW_ZENOH_CONFIG"
    }


@pytest.fixture
def fake_discovery_server() -> Iterator[socket.socket]:
    """A UDP socket on 127.0.0.2 (loopback: allowed) where a discovery server would listen."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.2", 0))
    sock.setblocking(False)
    yield sock
    sock.close()


def _datagrams(sock: socket.socket) -> int:
    count = 0
    while True:
        try:
            sock.recv(65536)
        except BlockingIOError:
            return count
        count += 1


def test_replay_sends_nothing_to_a_discovery_server_from_the_environment(
    ros_env: RosEnv, tmp_path: Path, fake_discovery_server: socket.socket
) -> None:
    host, port = fake_discovery_server.getsockname()
    env = {**ros_env.env, "ROS_DISCOVERY_SERVER": f"{host}:{port}"}
    out = tmp_path / "verdict.json"
    argv = [*CLI, "replay", str(EXAMPLE), "--json", str(out)]
    argv += ["--domain-id", str(ros_env.domain_id), "--timeout", "90"]
    replay = ManagedProcess("replay", argv, env)
    code = replay.wait(150)
    assert _datagrams(fake_discovery_server) == 0, "RTPS packets went to the discovery server"
    assert code == 0, replay.output
    assert json.loads(out.read_text())["verdict"]


def test_allow_external_discovery_flag_keeps_the_server(
    ros_env: RosEnv, fake_discovery_server: socket.socket
) -> None:
    """Opted in on the command line, the children do use the server (so the test above
    can see packets when they are sent)."""
    host, port = fake_discovery_server.getsockname()
    env = {**ros_env.env, "ROS_DISCOVERY_SERVER": f"{host}:{port}"}
    argv = [*CLI, "demo", str(EXAMPLE), "--allow-external-discovery", "--timeout", "5"]
    demo = ManagedProcess("demo", [*argv, "--domain-id", str(ros_env.domain_id)], env)
    demo.wait(90)
    assert "external discovery settings kept" in demo.output, demo.output
    assert _datagrams(fake_discovery_server) > 0


def test_node_started_by_hand_warns_and_the_variable_really_applies(
    ros_env: RosEnv, fake_discovery_server: socket.socket
) -> None:
    """The positive control of the test above: a node started by hand keeps the variable
    (its user chose it), says so in one line naming it, and Fast DDS does send there."""
    host, port = fake_discovery_server.getsockname()
    env = {
        k: v for k, v in ros_env.env.items() if k not in (PROFILES_VARIABLE, OWN_PROFILE_VARIABLE)
    }
    env["ROS_DISCOVERY_SERVER"] = f"{host}:{port}"
    params: dict[str, ParamValue] = {
        "log_path": str(EXAMPLE),
        "wait_for_subscribers": 1,
        "wait_timeout_s": 30.0,
    }
    node = ManagedProcess("player", node_command(PLAYER, params), env)
    try:
        deadline = time.monotonic() + 30
        received = 0
        while time.monotonic() < deadline and received == 0:
            time.sleep(0.2)
            received = _datagrams(fake_discovery_server)
    finally:
        node.stop()
    assert received > 0, node.output
    warnings = [line for line in node.output.splitlines() if "WARN" in line]
    assert [line for line in warnings if "ROS_DISCOVERY_SERVER is set" in line], node.output
    assert f"{host}:{port}" not in node.output


# --- the profile file ---------------------------------------------------------------------


def test_profile_is_private_and_never_follows_a_planted_symlink(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """Another user owns the shared temp folder's names: plant a symlink at the old fixed
    name and at every name the old code could derive from the next pids. The player still
    starts, nothing is written through a link, and it leaves no folder behind."""
    shared = tmp_path / "shared_tmp"
    shared.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    old = shared / f"ads_rca_fastdds_fast_ack_{os.getuid()}.xml"
    old.symlink_to(victim)
    probe = ManagedProcess("probe", [sys.executable, "-c", "pass"], ros_env.env)
    probe.wait(30)
    first = probe.process.pid
    for pid in range(first, first + 400):
        Path(f"{old}.{pid}").symlink_to(victim)
    planted = sorted(os.listdir(shared))

    env = {
        k: v for k, v in ros_env.env.items() if k not in (PROFILES_VARIABLE, OWN_PROFILE_VARIABLE)
    }
    env.update(TMPDIR=str(shared), TMP=str(shared), TEMP=str(shared))
    env.pop("XDG_RUNTIME_DIR", None)
    params: dict[str, ParamValue] = {"log_path": str(EXAMPLE), "rate": 0.0}
    player = ManagedProcess("player", node_command(PLAYER, params), env)
    assert player.wait(60) == 0, player.output
    assert "finished" in player.output
    assert victim.read_text() == "precious\n"
    assert sorted(os.listdir(shared)) == planted  # its own private folder is gone again
    assert all((shared / name).is_symlink() for name in planted)


def test_profile_directory_is_0700_and_file_0600(tmp_path: Path) -> None:
    path = Path(profile_file(loopback_only=True))
    folder = path.parent
    assert stat.S_IMODE(folder.lstat().st_mode) == 0o700 and not folder.is_symlink()
    assert stat.S_IMODE(path.lstat().st_mode) == 0o600 and not path.is_symlink()
    assert folder.name.startswith("ads_rca_fastdds_") and folder.lstat().st_uid == os.getuid()

    runtime = tmp_path / "runtime"
    runtime.mkdir(mode=0o700)
    assert private_parent({"XDG_RUNTIME_DIR": str(runtime)}) == str(runtime)
    runtime.chmod(0o755)  # readable by others: not private, fall back to mkdtemp in tmp
    assert private_parent({"XDG_RUNTIME_DIR": str(runtime)}) != str(runtime)
    link = tmp_path / "link"
    runtime.chmod(0o700)
    link.symlink_to(runtime)
    assert private_parent({"XDG_RUNTIME_DIR": str(link)}) != str(link)


# --- the sockets the nodes hold -----------------------------------------------------------


def _socket_inodes(pid: int) -> set[str]:
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    return inodes


def _udp_sockets(pid: int) -> list[tuple[str, int, int, str]]:
    """(family:address, port, rx_queue, inode) of every UDP socket ``pid`` holds."""
    mine = _socket_inodes(pid)
    found = []
    for table in ("udp", "udp6"):
        with open(f"/proc/{pid}/net/{table}") as rows:
            next(rows)
            for row in rows:
                fields = row.split()
                address, port = fields[1].split(":")
                if fields[9] not in mine:
                    continue
                if table == "udp":
                    address = ".".join(str(int(address[i : i + 2], 16)) for i in (6, 4, 2, 0))
                rx_queue = int(fields[4].split(":")[1], 16)
                found.append((address, int(port, 16), rx_queue, fields[9]))
    return found


def _ports_of_domain(domain_id: int) -> range:
    """RTPS well-known ports of a domain: PB 7400 + DG 250 * domain + the 250 of it."""
    base = 7400 + 250 * domain_id
    return range(base, base + 250)


def test_every_port_a_node_receives_on_is_bound_to_loopback(
    ros_env: RosEnv, tmp_path: Path
) -> None:
    """The whole graph (recorder, aggregator, monitors, player) with the player held
    waiting for subscribers, so every participant is up while its sockets are read."""
    spec = GraphSpec(
        log_path=EXAMPLE,
        params=make_params("corrected"),
        verdict_json=tmp_path / "verdict.json",
        namespace=ros_env.namespace,
        record=tmp_path / "bag",
        player_params={"wait_for_subscribers": 99, "wait_timeout_s": 60.0},
    )
    domain_ports = _ports_of_domain(ros_env.domain_id)
    with Graph(spec, ros_env.env) as graph:
        graph.start()
        pids = {name: p.process.pid for name, p in graph.processes.items()}
        sockets: dict[str, list[tuple[str, int, int, str]]] = {}
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(sockets) < len(pids):
            time.sleep(0.2)
            for name, pid in pids.items():
                found = _udp_sockets(pid)
                if sum(port in domain_ports for _, port, _, _ in found) >= 2:
                    sockets[name] = found
        assert sorted(sockets) == sorted(pids), graph.processes["player"].output
        sockets = {name: _udp_sockets(pid) for name, pid in pids.items()}
        others = []
        for name, found in sockets.items():
            for address, port, _, inode in found:
                # The domain's ports carry discovery and data: loopback only.
                assert address == "127.0.0.1" or port not in domain_ports, (name, found)
                if address != "127.0.0.1":
                    others.append((name, address, port, inode))
        # What is left off loopback are the send sockets of rmw_fastrtps's own LOCALHOST
        # UDP transport (appended without an interface list; its listening binds fail since
        # ours hold the ports). Prove nothing reads them: a datagram sent to each stays queued.
        assert all(address != "::" for _, address, _, _ in others), others
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for _, address, port, _ in others:
                sender.sendto(b"probe", ("127.0.0.1" if address == "0.0.0.0" else address, port))
        wait_for(lambda: all(_queued(pids[o[0]], o[3]) for o in others), 10, "queued probes")
        time.sleep(0.5)  # a socket somebody reads would be drained by now
        unread = [o for o in others if _queued(pids[o[0]], o[3])]
        assert unread == others, f"read by a node: {sorted(set(others) - set(unread))}"
        interfaces = _non_loopback_ipv4_addresses()
        for name in pids:
            assert sum(o[0] == name for o in others) <= 1 + len(interfaces), others


def _queued(pid: int, inode: str) -> bool:
    return any(i == inode and rx > 0 for _, _, rx, i in _udp_sockets(pid))


def wait_for(condition: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.1)


def _non_loopback_ipv4_addresses() -> list[str]:
    """This host's IPv4 addresses outside 127/8 (from the kernel's routing table)."""
    found = set()
    with open("/proc/net/fib_trie") as trie:
        previous = ""
        for line in trie:
            if "/32 host LOCAL" in line:
                address = previous.rsplit(maxsplit=1)[-1]
                if not address.startswith("127."):
                    found.add(address)
            previous = line
    return sorted(found)


@pytest.mark.parametrize("value", ["", "0", "yes", "true", " 1", "1 ", "01", "1\n"])
def test_only_exactly_1_opts_in_to_external_discovery(value: str, tmp_path: Path) -> None:
    """``ADS_RCA_ALLOW_EXTERNAL_DISCOVERY`` with anything but ``1`` keeps the rule: the
    variables that redirect discovery are cleared and our loopback profile is used."""
    from ads_rca.ros.env import ALLOW_EXTERNAL_VARIABLE, ros_environment

    base = {
        ALLOW_EXTERNAL_VARIABLE: value,
        "ROS_DISCOVERY_SERVER": "192.0.2.1:11811",
        "ROS_STATIC_PEERS": "192.0.2.2",
        "FASTDDS_DEFAULT_PROFILES_FILE": str(tmp_path / "theirs.xml"),
        "PATH": os.environ.get("PATH", ""),
    }
    env = ros_environment(domain_id=5, log_dir=tmp_path, base=base)
    assert "ROS_DISCOVERY_SERVER" not in env and "ROS_STATIC_PEERS" not in env
    assert env["FASTDDS_DEFAULT_PROFILES_FILE"] != str(tmp_path / "theirs.xml")
    assert ALLOW_EXTERNAL_VARIABLE not in env
