"""Attack surface: listening addresses, nothing evaluated or unpickled, MAVLink signing.

- A running ``sarmoco run`` has inet sockets bound only to the addresses its
  configuration names (127.0.0.1 by default), read from ``/proc/net`` and the
  daemon's own file descriptors.
- No module of ``sarmoco`` evaluates or unpickles anything (``eval``, ``exec``,
  ``pickle``, ``marshal``, ``shelve``, ``yaml.load``, ``allow_pickle=True``).
- With a signing key, a replayed signed frame and forged ones (a flipped signature
  byte, another key, unsigned) are rejected on a real UDP link, and good frames after
  them still pass.
"""

from __future__ import annotations

import ast
import os
import socket
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from sarmoco.app.simconfig import write_config
from sarmoco.daemon.config import Config, InsConfig, RadarConfig, config_to_dict
from sarmoco.daemon.status import STATUS_HOSTS
from sarmoco.drivers.mavlink import MavlinkSource, mavlink2
from sarmoco.errors import ConfigError
from tests.daemon.test_daemon_process import Daemon, free_port

PACKAGE = Path(__file__).resolve().parents[1] / "sarmoco"
KEY = bytes(range(1, 33))


def test_defaults_name_the_loopback_only() -> None:
    assert RadarConfig().link.startswith("udp://127.0.0.1:")
    assert InsConfig().link.startswith("udpin:127.0.0.1:")
    assert STATUS_HOSTS == ("127.0.0.1", "::1", "localhost")


def _inet_sockets(pid: int) -> list[tuple[str, str, int, int]]:
    """(protocol, local address, port, TCP state) of every inet socket ``pid`` holds."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    found = []
    for proto in ("tcp", "udp", "tcp6", "udp6"):
        for line in Path(f"/proc/net/{proto}").read_text().splitlines()[1:]:
            f = line.split()
            if f[9] not in inodes:
                continue
            addr_hex, port_hex = f[1].split(":")
            raw = bytes.fromhex(addr_hex)
            if len(raw) == 4:
                addr = socket.inet_ntop(socket.AF_INET, raw[::-1])
            else:  # four little-endian 32-bit words
                words = b"".join(raw[i : i + 4][::-1] for i in range(0, 16, 4))
                addr = socket.inet_ntop(socket.AF_INET6, words)
            found.append((proto, addr, int(port_hex, 16), int(f[3], 16)))
    return found


def test_daemon_listens_only_on_the_configured_addresses(tmp_path: Path) -> None:
    """Radar on 127.0.0.2 (configured), MAVLink and status on 127.0.0.1: the daemon's
    sockets are exactly those, and the one TCP socket is the status listener."""
    radar_port, ins_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    http_port = free_port(socket.SOCK_STREAM)
    table = config_to_dict(Config())
    table["ins"]["lever_arm_m"] = list(table["ins"]["lever_arm_m"])
    table["radar"]["link"] = f"udp://127.0.0.2:{radar_port}"
    table["ins"]["link"] = f"udpin:127.0.0.1:{ins_port}"
    table["status"]["http_port"] = http_port
    table["recorder"]["directory"] = str(tmp_path)
    config = write_config(tmp_path / "sarmoco.toml", table)
    d = Daemon(config, tmp_path / "run.zarr")
    try:
        d.started()
        sockets = _inet_sockets(d.proc.pid)
        assert d.stop() == 0
    finally:
        d.kill_if_running()
    tcp_listen = 0x0A
    assert sorted(sockets) == sorted([
        ("udp", "127.0.0.2", radar_port, 7),
        ("udp", "127.0.0.1", ins_port, 7),
        ("tcp", "127.0.0.1", http_port, tcp_listen),
    ]), sockets  # fmt: skip


FORBIDDEN_CALLS = {"eval", "exec", "compile", "__import__"}
FORBIDDEN_MODULES = {"pickle", "cPickle", "dill", "marshal", "shelve", "joblib", "yaml"}


def test_nothing_is_evaluated_or_unpickled() -> None:
    """No module of sarmoco calls eval/exec/compile, imports a pickling or YAML module,
    or passes ``allow_pickle=True`` (numpy and zarr object arrays)."""
    bad = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            where = f"{path.relative_to(PACKAGE.parent)}:{getattr(node, 'lineno', 0)}"
            if isinstance(node, ast.Call):
                fn = node.func
                name = fn.id if isinstance(fn, ast.Name) else None
                if name in FORBIDDEN_CALLS:
                    bad.append(f"{where} calls {name}")
                for kw in node.keywords:
                    if kw.arg == "allow_pickle" and not (
                        isinstance(kw.value, ast.Constant) and kw.value.value is False
                    ):
                        bad.append(f"{where} passes allow_pickle")
            elif isinstance(node, ast.Import | ast.ImportFrom):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else [
                    node.module or ""]  # fmt: skip
                for n in names:
                    if n.split(".")[0] in FORBIDDEN_MODULES:
                        bad.append(f"{where} imports {n}")
    assert not bad, bad


def test_the_ast_check_sees_what_it_forbids(tmp_path: Path) -> None:
    """The checker above is not blind: each forbidden form in a sample is found."""
    code = "import pickle\nfrom yaml import load\nx = eval('1')\nnp.load(f, allow_pickle=True)\n"
    tree = ast.parse(code)
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)]
    imports = [n for n in ast.walk(tree) if isinstance(n, ast.Import | ast.ImportFrom)]
    assert any(isinstance(c.func, ast.Name) and c.func.id in FORBIDDEN_CALLS for c in calls)
    assert any(kw.arg == "allow_pickle" for c in calls for kw in c.keywords)
    assert len(imports) == 2


def _signed(key: bytes, port: int) -> mavutil.mavfile:
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1,
                                      source_component=1)  # fmt: skip
    conn.setup_signing(key, sign_outgoing=True)
    return conn


def _frame(conn: mavutil.mavfile, k: int) -> bytes:
    msg = mavlink2.MAVLink_local_position_ned_message(1000 + k, 0, 0, 0, float(k), 0, 0)
    return bytes(msg.pack(conn.mav))


def test_signing_rejects_replayed_and_forged_frames() -> None:
    src = MavlinkSource("udpin:127.0.0.1:0", signing_key=KEY, host_clock_is_utc=False)
    port = src._conn.port.getsockname()[1]
    good = _signed(KEY, port)
    rogue = _signed(bytes(32), port)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.connect(("127.0.0.1", port))

    def send(frame: bytes) -> tuple[int, int]:
        """Frames accepted and rejected by the source for one datagram."""
        before = (src.counters.frames, src.counters.rejected)
        tx.send(frame)
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            src.poll(0.01)
            after = (src.counters.frames, src.counters.rejected)
            if after != before:
                return after[0] - before[0], after[1] - before[1]
        return 0, 0

    try:
        first = _frame(good, 1)
        assert send(first) == (1, 0)  # signed with the key: accepted
        assert send(first) == (0, 1)  # the same frame again (timestamp, link id): replay
        flipped = bytearray(_frame(good, 2))
        flipped[-1] ^= 0x01  # the signature's last byte (the CRC does not cover it)
        assert send(bytes(flipped)) == (0, 1)
        assert send(_frame(rogue, 3)) == (0, 1)  # signed with another key
        unsigned = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        assert send(bytes(mavlink2.MAVLink_local_position_ned_message(
            1004, 0, 0, 0, 4.0, 0, 0).pack(unsigned))) == (0, 1)  # fmt: skip
        assert send(_frame(good, 5)) == (1, 0)  # the link still takes good frames
    finally:
        tx.close()
        good.close()
        rogue.close()
        src.close()


@pytest.mark.parametrize("bad_key", [b"", bytes(31), bytes(33)])
def test_a_signing_key_of_the_wrong_length_is_refused(bad_key: bytes) -> None:
    """Refused with a ConfigError naming the key, before a socket is opened (none leaks)."""
    fds = len(os.listdir("/proc/self/fd"))
    with pytest.raises(ConfigError, match="signing_key"):
        MavlinkSource("udpin:127.0.0.1:0", signing_key=bad_key)
    assert len(os.listdir("/proc/self/fd")) == fds
