"""The live daemon as a real process (``python -m sarmoco run``): crashes, stops, status, bad input.

The radar and INS come from ``sarmoco sim --out`` files (a scaled ku-vehicle run of
1000 pulses, which fits the echo ring, so a file link is read without drops), either
as file links or replayed by the test over UDP on 127.0.0.1. Every check reads the
store back with :func:`sarmoco.store.reader.open_store` and compares it with the
files decoded by the drivers (:class:`~sarmoco.drivers.radar.RadarFileSource`, the
MAVLink source of the ``.tlog``).

- SIGKILL at random moments while recording (12 daemons, 4 at a time): the store
  opens, every committed pulse and INS row equals the files', nothing past
  ``committed`` is read.
- SIGTERM: exit status 0, store complete, every pulse read recorded, xarray reads it.
- sd_notify on a real AF_UNIX datagram socket: READY=1, WATCHDOG=1 while healthy (every
  half watchdog period, not every loop pass), STATUS=, STOPPING=1 at SIGTERM.
- The HTTP status endpoint: /status, /metrics, /health.

File links, INS bytes, bad configuration and garbage input: tests/daemon/test_daemon_files.py
(a module of its own, so that `make test`'s realtime phase runs it beside this one).
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import tomllib
import urllib.error
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
import xarray as xr
import zarr
from pymavlink import mavutil

from sarmoco.app.simconfig import write_config
from sarmoco.daemon.config import load_config
from sarmoco.daemon.links import open_ins, vita_decoder
from sarmoco.daemon.runner import replay_store
from sarmoco.drivers.radar import RadarFileSource
from sarmoco.drivers.samples import AttitudeSample, VelocitySample
from sarmoco.drivers.vita49 import VitaStreamFramer
from sarmoco.errors import DataFileError
from sarmoco.store.flags import NAV_UNUSABLE
from sarmoco.store.reader import RunStore, open_store

SCALE = 0.05
N_PULSES = 1000
"""Pulses simulated: fewer than the echo ring holds (1024 at this PRF), so none is dropped."""

START_TIMEOUT_S = 60.0
"""Longest wait for a daemon to open its links and print its JSON line, s."""

KILL_TRIALS, KILL_PARALLEL = 12, 4
KILL_WINDOW_S = 2.0
"""SIGKILLs land uniformly within this long after a wave of daemons is up, s."""

WATCHDOG_USEC = 1_000_000
PY = [sys.executable, "-m", "sarmoco"]


@dataclass(frozen=True)
class SimFiles:
    """The simulator's files and what the drivers decode from them."""

    dir: Path
    table: dict[str, Any]
    t_ns: npt.NDArray[np.int64]
    echo: npt.NDArray[np.int16]
    packets: list[bytes]
    nav: list[VelocitySample | AttitudeSample]


def decode_radar(
    cfg_path: Path, vrt: Path, n_pulses: int = N_PULSES
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int16]]:
    """Pulse times (GPS ns) and int16 I/Q echoes of a ``.vrt`` file, read by the radar driver."""
    cfg = load_config(cfg_path)
    rows = np.empty((n_pulses + 64, cfg.radar.n_samples, 2), np.int16)
    t: list[int] = []
    with RadarFileSource(vrt, vita_decoder(cfg)) as src:
        while not src.eof:
            t += [p.t_gps_ns for p in src.read_into(rows[len(t) :], 0.0)]
    return np.array(t, dtype=np.int64), rows[: len(t)].copy()


def vita_packets(cfg_path: Path, vrt: Path) -> list[bytes]:
    """The packets of a ``.vrt`` file, cut by the driver's stream framer."""
    decoder = vita_decoder(load_config(cfg_path))
    framer = VitaStreamFramer(decoder)
    framer.feed(vrt.read_bytes())
    row = np.empty((decoder.n_samples, 2), np.int16)
    out = []
    while (packet := framer.next_packet()) is not None:
        out.append(bytes(packet))
        decoder.decode_into(packet, row)
        framer.consume(packet, decoder.last_ok)
    return out


def decode_nav(cfg_path: Path) -> list[VelocitySample | AttitudeSample]:
    """Velocity and attitude samples of the configured INS log, in file order."""
    out: list[VelocitySample | AttitudeSample] = []
    with open_ins(load_config(cfg_path)) as src:
        while not src.eof:
            out += [s for s in src.poll(0.0) if isinstance(s, VelocitySample | AttitudeSample)]
    return out


def simulate_files(out: Path, n_pulses: int) -> None:
    """``sarmoco sim --out``: the scaled ku-vehicle run of ``n_pulses`` pulses in ``out``."""
    subprocess.run(
        [*PY, "sim", "--preset", "ku-vehicle", "--scale", str(SCALE), "--pulses",
         str(n_pulses), "--motion", "turbulence", "--motion-seed", "1", "--ins-grade",
         "tactical", "--out", str(out)],
        check=True, capture_output=True,
    )  # fmt: skip


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> SimFiles:
    out = tmp_path_factory.mktemp("sim")
    simulate_files(out, N_PULSES)
    cfg_path = out / "sarmoco.toml"
    t_ns, echo = decode_radar(cfg_path, out / "radar.vrt")
    assert t_ns.size == N_PULSES
    with cfg_path.open("rb") as fh:
        table = tomllib.load(fh)
    packets = vita_packets(cfg_path, out / "radar.vrt")
    return SimFiles(out, table, t_ns, echo, packets, decode_nav(cfg_path))


def daemon_config(sim: SimFiles, path: Path, **sections: dict[str, Any]) -> Path:
    """The simulator's configuration with sections overridden; status endpoint off by default."""
    table = {name: dict(values) for name, values in sim.table.items()}
    table["status"] = {"http_port": 0}
    for name, values in sections.items():
        table.setdefault(name, {}).update(values)
    return write_config(path, table)


def free_port(kind: socket.SocketKind) -> int:
    """A port on 127.0.0.1 that is free right now (TCP or UDP)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Daemon:
    """A ``sarmoco run`` subprocess; stderr (the JSON log) goes to ``log`` (``<store>.log``)."""

    def __init__(
        self,
        config: Path,
        store: Path,
        env: dict[str, str] | None = None,
        log: Path | None = None,
    ) -> None:
        self.store = store
        self.log = log or store.with_suffix(".log")
        with self.log.open("w") as err:
            self.proc = subprocess.Popen(
                [*PY, "run", "--config", str(config), "--store", str(store)],
                stdout=subprocess.PIPE, stderr=err, text=True, env=env,
            )  # fmt: skip

    def started(self) -> dict[str, Any]:
        """Wait for the daemon's JSON line (links open, recorder created); return it."""
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], START_TIMEOUT_S)
        line = self.proc.stdout.readline() if ready else ""
        assert line.startswith("{"), f"daemon did not start: {line!r}\n{self.log.read_text()}"
        hello: dict[str, Any] = json.loads(line)
        return hello

    def stop(self, sig: signal.Signals = signal.SIGTERM, timeout_s: float = 60.0) -> int:
        """Send ``sig`` and wait for the exit status."""
        self.proc.send_signal(sig)
        return self.proc.wait(timeout_s)

    def kill_if_running(self) -> None:
        """SIGKILL the daemon if it still runs (test clean-up) and close its pipe."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()


def http_get(port: int, path: str) -> tuple[int, str]:
    """GET http://127.0.0.1:PORT/PATH; returns (status code, body)."""
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=10) as resp:
            return int(resp.status), resp.read().decode()
    except urllib.error.HTTPError as exc:
        return int(exc.code), exc.read().decode()


def wait_status(port: int, group: str, name: str, at_least: float) -> dict[str, Any]:
    """Poll /status until ``status[group][name] >= at_least``; return that document."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        status: dict[str, Any] = json.loads(http_get(port, "/status")[1])
        if status[group].get(name, -1) >= at_least:
            return status
        assert time.monotonic() < deadline, f"{group}/{name} >= {at_least} not reached: {status}"
        time.sleep(0.1)


def wait_finished(port: int) -> dict[str, Any]:
    """Poll /status until both file links are read to their end; return that document."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        status: dict[str, Any] = json.loads(http_get(port, "/status")[1])
        links = status["components"].get("links", {"detail": ""})["detail"]
        if "radar: finished" in links and "ins: finished" in links:
            return status
        assert time.monotonic() < deadline, status
        time.sleep(0.1)


def wait_received(port: int, n_pulses: int) -> None:
    """Poll /status until the pipeline has taken ``n_pulses``."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        status = json.loads(http_get(port, "/status")[1])
        if status["counters"].get("pipeline_pulses_received", 0) >= n_pulses:
            return
        assert time.monotonic() < deadline, status
        time.sleep(0.1)


def wait_focused(port: int) -> None:
    """Poll /status until no recorded pulse waits to be focused."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        status = json.loads(http_get(port, "/status")[1])
        if status["gauges"].get("focus_backlog_pulses", 1) == 0:
            return
        assert time.monotonic() < deadline, status
        time.sleep(0.1)


def run_files_to_end(config: Path, store: Path, port: int) -> tuple[RunStore, dict[str, Any]]:
    """Run the daemon on file links until both are read to their end, stop it (exit 0);
    returns its store and the last /status document."""
    d = Daemon(config, store)
    try:
        d.started()
        status = wait_finished(port)
        assert d.stop() == 0, d.log.read_text()
    finally:
        d.kill_if_running()
    return open_store(store), status


def check_committed(store: RunStore, sim: SimFiles) -> int:
    """Every committed pulse and INS row equals the files'; returns the committed pulses."""
    n = check_pulses(store, sim)
    rows = nav_rows(store)
    assert rows == [nav_row(s) for s in sim.nav[: len(rows)]]
    return n


def check_pulses(store: RunStore, sim: SimFiles, gaps: bool = False) -> int:
    """Every committed pulse equals the file's; nothing past ``committed`` is read.

    ``gaps``: the run had refused writes (a full disk), so blocks whose write failed may be
    missing: the pulse ids then need only increase, and each row equals the file's pulse of
    its id (without a writer thread a failed block's rows are taken by the next block, whose
    write may succeed once zarr has removed the failed write's partial file)."""
    n = store.committed("pulses")
    got = store.read("pulses")
    assert {a.shape[0] for a in got.values()} == {n}
    ids = np.arange(n)
    if gaps:
        ids = got["pulse_id"].astype(np.int64)
        assert (np.diff(ids) > 0).all() and ids[-1] < sim.t_ns.size, ids
    np.testing.assert_array_equal(got["pulse_id"], ids)
    np.testing.assert_array_equal(got["t_ns"], sim.t_ns[ids])
    np.testing.assert_array_equal(got["echo"], sim.echo[ids])
    np.testing.assert_array_equal(got["channel"], 0)
    assert not (got["flags"] & ~np.uint32(NAV_UNUSABLE)).any()  # no receiver or drop flags
    allocated = zarr.open_array(str(store.path / "pulses" / "t_ns"), mode="r").shape[0]
    assert allocated >= n
    assert store.read("pulses", ["t_ns"], 0, allocated + 100)["t_ns"].shape[0] == n
    assert store.dataset("pulses").sizes["pulse"] == n
    return n


NavRow = tuple[int, int, tuple[float, ...]]
"""An INS row as recorded: (t_ns, kind, velocity NED m/s or attitude quaternion)."""


def nav_row(s: VelocitySample | AttitudeSample) -> NavRow:
    """The row the daemon records for a decoded INS sample."""
    if isinstance(s, VelocitySample):
        return s.t_gps_ns, 0, s.vel_ned
    return s.t_gps_ns, 1, s.quat


def nav_rows(store: RunStore) -> list[NavRow]:
    """The committed INS rows of a store."""
    nav = store.read("nav", ["t_ns", "kind", "vel_ned", "quat"])
    return [
        (int(t), int(k), tuple(float(x) for x in (v if k == 0 else q)))
        for t, k, v, q in zip(nav["t_ns"], nav["kind"], nav["vel_ned"], nav["quat"], strict=True)
    ]


# -- SIGKILL --------------------------------------------------------------------------------


def test_sigkill_at_random_moments_leaves_committed_pulses_intact(
    sim: SimFiles, tmp_path: Path
) -> None:
    """12 daemons recording the file links (4 at a time), each SIGKILLed at a random moment.

    Small blocks, chunks and fsync interval make the recording last a second or more
    (about 125 appends of 8 pulses, each fsynced), so the kills land while recording.
    """
    config = daemon_config(
        sim, tmp_path / "kill.toml", imaging={"block_pulses": 8},
        recorder={"chunk_pulses": 8, "fsync_interval_s": 0.001},
    )  # fmt: skip
    rng = np.random.default_rng(20261122)
    t0 = time.monotonic()
    committed: list[int] = []
    for wave in range(KILL_TRIALS // KILL_PARALLEL):
        daemons = [Daemon(config, tmp_path / f"kill{wave}-{k}.zarr") for k in range(KILL_PARALLEL)]
        try:
            for d in daemons:
                d.started()
            t_up = time.monotonic()
            delays = rng.uniform(0.0, KILL_WINDOW_S, KILL_PARALLEL)
            for delay, d in sorted(zip(delays, daemons, strict=True), key=lambda p: p[0]):
                time.sleep(max(0.0, t_up + delay - time.monotonic()))
                d.proc.send_signal(signal.SIGKILL)
            for d in daemons:
                assert d.proc.wait(10) == -signal.SIGKILL
        finally:
            for d in daemons:
                d.kill_if_running()
        for d in daemons:
            store = open_store(d.store)
            assert store.attrs["complete"] is False
            committed.append(check_committed(store, sim))
    elapsed = time.monotonic() - t0
    print(f"{KILL_TRIALS} SIGKILLs in {elapsed:.1f} s; committed pulses: {committed}")
    assert len(set(committed)) >= 4, committed  # the kills landed at different moments
    assert sum(0 < n < N_PULSES for n in committed) >= 3, committed  # several mid-recording


# -- SIGTERM ---------------------------------------------------------------------------------


def test_sigterm_flushes_every_pulse_read_and_exits_0(sim: SimFiles, tmp_path: Path) -> None:
    """SIGTERM as soon as the whole file is read: pulses still waiting for the INS are flushed."""
    port = free_port(socket.SOCK_STREAM)
    config = daemon_config(sim, tmp_path / "term.toml", status={"http_port": port})
    d = Daemon(config, tmp_path / "term.zarr")
    try:
        assert d.started()["status_port"] == port
        status = wait_status(port, "counters", "radar_frames", len(sim.packets))
        assert d.stop() == 0, d.log.read_text()
    finally:
        d.kill_if_running()
    assert status["counters"]["radar_parse_errors"] == 0
    store = open_store(d.store)
    assert store.attrs["complete"] is True
    assert store.committed("pulses") == N_PULSES == store.attrs["metrics"]["pulses_received"]
    assert check_committed(store, sim) == N_PULSES
    assert store.committed("nav") == store.attrs["metrics"]["nav_samples"] > 0
    pulses = xr.open_zarr(d.store, group="pulses", consolidated=False)
    assert dict(pulses.sizes) == {"pulse": N_PULSES, "sample": sim.echo.shape[1], "iq": 2}
    np.testing.assert_array_equal(pulses["t_ns"].values, sim.t_ns)
    np.testing.assert_array_equal(pulses["echo"][-3:].values, sim.echo[-3:])
    nav = xr.open_zarr(d.store, group="nav", consolidated=False)
    assert nav.sizes["nav"] == store.committed("nav")
    log = [json.loads(line) for line in d.log.read_text().splitlines()]
    assert log[-1]["msg"] == "sarmoco stopped" and log[-1]["pulses_received"] == N_PULSES


# -- live links: sd_notify and the status endpoint -----------------------------------------


@dataclass
class LiveRun:
    """What a daemon on UDP links showed while the test fed it."""

    notes: list[tuple[float, str]] = field(default_factory=list)
    t_term: float = 0.0
    exit_status: int | None = None
    pages: dict[str, tuple[int, str]] = field(default_factory=dict)
    healthy_pages: dict[str, tuple[int, str]] = field(default_factory=dict)
    hello: dict[str, Any] = field(default_factory=dict)
    packets_sent: int = 0
    frames_sent: list[bytes] = field(default_factory=list)
    store: Path = Path()
    config: Path = Path()


def mavlink_frames(tlog: Path, n: int) -> list[bytes]:
    """The first ``n`` MAVLink frames of a telemetry log, as sent on the wire."""
    conn = mavutil.mavlink_connection(str(tlog))
    frames: list[bytes] = []
    while len(frames) < n and (msg := conn.recv_match()) is not None:
        frames.append(bytes(msg.get_msgbuf()))
    conn.close()
    return frames


class NotifyListener:
    """An AF_UNIX datagram socket in systemd's place: keeps every note with its arrival time.

    Parameters
    ----------
    path : Path
        Where the socket is bound (``NOTIFY_SOCKET``).
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.notes: list[tuple[float, str]] = []
        """(seconds since the listener started, the datagram's text)."""
        self._t0 = time.monotonic()
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._sock.bind(str(path))
        self._sock.settimeout(0.1)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._listen, daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        while not self._stop.is_set():
            try:
                note = self._sock.recv(4096).decode()
            except TimeoutError:
                continue
            self.notes.append((self.now(), note))

    def now(self) -> float:
        """Seconds since the listener started (the time base of :attr:`notes`)."""
        return time.monotonic() - self._t0

    def env(self, watchdog_usec: int) -> dict[str, str]:
        """The environment of a daemon that systemd watches with ``WATCHDOG_USEC``."""
        return dict(os.environ, NOTIFY_SOCKET=str(self.path), WATCHDOG_USEC=str(watchdog_usec))

    def pings(self) -> list[float]:
        """Arrival times of the WATCHDOG=1 notes."""
        return [t for t, note in self.notes if "WATCHDOG=1" in note.splitlines()]

    def next_ping(self, after: float, timeout_s: float = 30.0) -> float:
        """Arrival time of the first WATCHDOG=1 note later than ``after`` (the time base of
        :attr:`notes`), waited for up to ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not (later := [t for t in self.pings() if t > after]):
            assert time.monotonic() < deadline, self.notes
            time.sleep(0.05)
        return later[0]

    def close(self) -> None:
        """Stop listening and close the socket."""
        self._stop.set()
        self._thread.join()
        self._sock.close()


@pytest.fixture(scope="module")
def live(sim: SimFiles, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveRun]:
    """A daemon on UDP radar + MAVLink/UDP links, NOTIFY_SOCKET and WATCHDOG_USEC set.

    The test sends the ``.vrt`` packets as datagrams, reads the status pages while no
    INS has spoken (unhealthy), then sends MAVLink frames of the ``.tlog`` (healthy),
    reads them again, and stops the daemon with SIGTERM; every notification is kept.
    """
    tmp = tmp_path_factory.mktemp("live")
    radar_port, ins_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    http_port = free_port(socket.SOCK_STREAM)
    config = daemon_config(
        sim, tmp / "live.toml",
        radar={"link": f"udp://127.0.0.1:{radar_port}"},
        ins={"link": f"udpin:127.0.0.1:{ins_port}"},
        status={"http_port": http_port},
    )  # fmt: skip
    run = LiveRun()
    notify = NotifyListener(tmp / "notify.sock")
    run.notes = notify.notes
    env = notify.env(WATCHDOG_USEC)
    d = Daemon(config, tmp / "live.zarr", env)
    run.store, run.config = d.store, config
    try:
        run.hello = d.started()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for k, packet in enumerate(sim.packets):
                tx.sendto(packet, ("127.0.0.1", radar_port))
                run.packets_sent += 1
                if k % 50 == 49:
                    time.sleep(0.01)  # bursts well within the socket buffer
            wait_status(http_port, "counters", "pipeline_pulses_received", N_PULSES)
            for page in ("/status", "/metrics", "/health", "/nothing"):
                run.pages[page] = http_get(http_port, page)
            run.frames_sent = mavlink_frames(sim.dir / "nav.tlog", 200)
            for frame in run.frames_sent:
                tx.sendto(frame, ("127.0.0.1", ins_port))
                time.sleep(0.002)
        wait_status(http_port, "counters", "ins_frames", 100)
        time.sleep(1.2)  # one more pass of the health check and a STATUS line
        for page in ("/status", "/health"):
            run.healthy_pages[page] = http_get(http_port, page)
        run.t_term = notify.now()
        run.exit_status = d.stop()
        time.sleep(0.3)
    finally:
        d.kill_if_running()
        notify.close()
    yield run


def test_sd_notify_ready_watchdog_status_stopping(live: LiveRun) -> None:
    assert live.exit_status == 0
    notes = [(t, dict(line.split("=", 1) for line in note.splitlines())) for t, note in live.notes]
    # before READY=1 only the kernels' warm-up speaks (extending the start-up timeout)
    ready = next(k for k, (_, n) in enumerate(notes) if n.get("READY") == "1")
    assert all(set(n) <= {"STATUS", "EXTEND_TIMEOUT_USEC"} for _, n in notes[:ready]), notes
    keys = notes[ready:]
    assert live.hello["store"] in keys[0][1]["STATUS"]
    pings = [t for t, k in keys if k.get("WATCHDOG") == "1"]
    assert len(pings) >= 3
    assert pings[0] >= keys[0][0] and pings[-1] < live.t_term + 1.0
    gaps = np.diff([keys[0][0], *pings, live.t_term])
    assert gaps.max() < WATCHDOG_USEC / 1e6, gaps.max()  # never a watchdog period without one
    # at most one ping per half period (sd_watchdog_enabled(3)), not one per loop pass
    assert np.diff(pings).min() >= 0.9 * WATCHDOG_USEC / 2e6, np.diff(pings)
    statuses = [k["STATUS"] for _, k in keys[1:] if "STATUS" in k]
    assert len(statuses) >= 2
    assert any(s.startswith(f"{N_PULSES} pulses, INS age") and "backlog" in s for s in statuses)
    stopping = [t for t, k in keys if k.get("STOPPING") == "1"]
    assert len(stopping) == 1 and stopping[0] >= live.t_term
    assert all(t <= stopping[0] for t in pings)  # no keep-alive after shutdown began


def test_live_ins_bytes_are_the_frames_received(live: LiveRun) -> None:
    """MAVLink over UDP: the store's raw INS bytes are a telemetry log of the frames sent,
    and a replay of the store carries them over."""
    store = open_store(live.store)
    assert store.attrs["ins_raw"] == {"format": "tlog"}
    tlog = live.store.with_suffix(".raw.tlog")
    tlog.write_bytes(store.ins_bytes())
    assert mavlink_frames(tlog, 10**6) == live.frames_sent
    replayed = live.store.with_suffix(".replay.zarr")
    # the run's INS stops before its pulses (the health test needs it stale): the replay
    # focuses nothing and says so, and still writes a complete store with the bytes
    with pytest.raises(DataFileError, match="focused no pulse"):
        replay_store(load_config(live.config), live.store, replayed, progress=False)
    again = open_store(replayed)
    assert again.attrs["ins_raw"] == {"format": "tlog"}
    assert again.ins_bytes() == store.ins_bytes()  # a replay carries the bytes over


def test_status_endpoint_serves_json_prometheus_and_health(live: LiveRun) -> None:
    code, body = live.pages["/status"]
    assert code == 200
    status = json.loads(body)
    assert status["counters"]["radar_frames"] == live.packets_sent
    assert status["counters"]["radar_parse_errors"] == 0
    assert status["counters"]["pipeline_pulses_received"] == N_PULSES
    assert status["gauges"]["echo_backlog_pulses"] == 0
    assert status["healthy"] is False and status["components"]["ins"]["ok"] is False
    assert status["uptime_s"] > 0
    code, metrics = live.pages["/metrics"]
    assert code == 200
    samples = {
        line.split(" ")[0]: float(line.split(" ")[1])
        for line in metrics.splitlines()
        if line and not line.startswith("#")
    }
    assert samples["sarmoco_pipeline_pulses_received_total"] == N_PULSES
    assert samples["sarmoco_pipeline_pulses_dropped_ring_total"] == 0
    assert samples["sarmoco_radar_frames_total"] == status["counters"]["radar_frames"]
    assert samples['sarmoco_component_up{component="ins"}'] == 0
    code, body = live.pages["/health"]
    assert code == 503 and "ins" in json.loads(body)
    assert live.pages["/nothing"][0] == 404
    code, body = live.healthy_pages["/health"]
    assert (code, body) == (200, "ok\n"), live.healthy_pages["/status"]
    healthy = json.loads(live.healthy_pages["/status"][1])
    assert healthy["healthy"] is True and healthy["counters"]["ins_frames"] >= 100
    types = dict(line.split(" ")[2:4] for line in metrics.splitlines() if line.startswith("# TYPE"))
    # Prometheus naming: a "_total" series is a counter (promtool lints a gauge so named).
    not_counters = sorted(
        n for n, kind in types.items() if n.endswith("_total") and kind != "counter"
    )
    assert not not_counters, f"typed gauge but named _total: {not_counters}"
