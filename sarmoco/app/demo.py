"""``sarmoco demo``: the simulated hardware and the daemon on loopback, then the report.

``sarmoco sim --serve`` plays a scaled ``ku-vehicle`` scenario in real time over the
real wire protocols to ``sarmoco run``, which focuses and records it; then the
report (quicklooks and metrics) is written next to the store. The demo uses
MAVLink over UDP and VITA 49 over UDP; the end-to-end tests use the other links.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.app.simcommand import platform_arguments, scenario_overrides
from sarmoco.app.simconfig import loopback_config
from sarmoco.app.truth import read_true_motion
from sarmoco.errors import SarmocoError
from sarmoco.products.report import ReportSummary, write_report
from sarmoco.sim.extended import load_scene
from sarmoco.sim.insemitters import INS_EMITTERS

PRESET = "ku-vehicle"
DAEMON_START_S = 60.0
"""How long the simulator or the daemon may take to open its links, s."""

SIM_TIMEOUT_S = 600.0
"""Longest a simulated run may play, s."""

IDLE_EXIT_S = 2.0
"""The daemon stops by itself (as on SIGTERM) once no pulse came for this long, s."""

DRAIN_TIMEOUT_S = 300.0
"""After the simulator is done, how long the daemon may take to catch up before SIGTERM, s."""

PATCH_MARGIN_M = 1.0
"""The extended scene's comparison window reaches this far beyond its clutter patch, m."""


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that is free right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def read_json_line(proc: subprocess.Popen[str], what: str, timeout_s: float) -> dict[str, Any]:
    """Read stdout lines of ``proc`` until one parses as a JSON object."""
    deadline = time.monotonic() + timeout_s
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            raise SarmocoError(f"demo: {what} exited (status {proc.wait()}) before it was ready")
        if line.lstrip().startswith("{"):
            record: dict[str, Any] = json.loads(line)
            return record
    raise SarmocoError(f"demo: {what} not ready after {timeout_s:.0f} s")


def _connect_link(info: dict[str, Any] | str) -> str:
    """The daemon's link string for what the simulator says to connect to."""
    if isinstance(info, str):
        return info
    return f"{info['interface']}:{info['channel']}"


def _wait_for_both(sim: subprocess.Popen[str], daemon: subprocess.Popen[str]) -> None:
    """Wait for the simulator to finish, then for the daemon to stop when idle (SIGTERM after
    ``DRAIN_TIMEOUT_S``); either failing raises :class:`SarmocoError`."""
    if sim.wait(timeout=SIM_TIMEOUT_S) != 0:
        raise SarmocoError(f"demo: the simulator failed (status {sim.returncode})")
    try:
        status = daemon.wait(timeout=DRAIN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        daemon.send_signal(signal.SIGTERM)
        status = daemon.wait(timeout=120)
    if status != 0:
        raise SarmocoError(f"demo: the daemon stopped with status {status}")


def run_loopback(
    out: Path,
    scale: float = 0.1,
    ins: str = "mavlink",
    radar: str = "udp",
    motion: str = "turbulence",
    platform: Sequence[str] = (),
    faults: Sequence[str] = (),
    scene: str = "points",
    daemon_env: Mapping[str, str] | None = None,
    **sections: dict[str, Any],
) -> ReportSummary:
    """Play a scaled ku-vehicle scenario from ``sarmoco sim --serve`` into ``sarmoco run``.

    The simulator starts first (it opens the pseudo-terminals and the TCP radar port and
    waits for the daemon); the daemon gets a configuration that matches the scenario and
    the links the simulator announced. When the simulator is done the daemon drains what
    it has received and stops by itself once the radar has been idle for 2 s (the same
    clean stop as SIGTERM: flush, close the store, exit 0), and the report is written.

    Parameters
    ----------
    out : Path
        Output folder: ``sarmoco.toml``, ``truth.json``, ``run.zarr``, ``report/``.
    scale : float
        Scenario scale (``sarmoco sim --scale``).
    ins : str
        INS protocol (a key of :data:`~sarmoco.sim.insemitters.INS_EMITTERS`) on its
        loopback link: MAVLink over UDP, SBG over a pty, SBG CAN through slcan on a pty.
    radar : {"udp", "tcp"}
        VITA 49 transport.
    motion : str
        Platform motion (``sarmoco sim --motion``).
    platform : sequence of str
        Extra ``sarmoco sim`` arguments of the platform (``--heading-deg``, ``--look-side``,
        ``--lever-arm``); the daemon's configuration follows them.
    faults : sequence of str
        Simulator fault switches (``sarmoco sim --fault``, e.g. ``"loss=0.02@radar"``).
    scene : str
        ``sarmoco sim --scene``: "points" (the preset's targets) or "extended" (terrain
        clutter and corner reflectors, :mod:`sarmoco.sim.extended`); the report's
        comparison then covers the whole clutter patch.
    daemon_env : mapping of str to str, optional
        Variables added to the daemon's environment only (e.g. a preloaded library that
        shifts the wall clock it sees).
    **sections : dict
        Extra configuration keys per section (e.g. ``autofocus={"enabled": False}``).

    Returns
    -------
    ReportSummary
        The report summary.
    """
    out.mkdir(parents=True, exist_ok=True)
    radar_url = f"udp://127.0.0.1:{free_udp_port()}" if radar == "udp" else "tcp://127.0.0.1:0"
    py = [sys.executable, "-m", "sarmoco"]
    sim = subprocess.Popen(
        [*py, "sim", "--preset", PRESET, "--scale", str(scale), "--motion", motion,
         "--motion-seed", "1", "--ins-grade", "tactical", "--serve", "--radar", radar_url,
         "--ins", f"{ins}:{INS_EMITTERS[ins].loopback.format(port=free_udp_port())}",
         "--truth", str(out / "truth.json"), "--scene", scene, *platform,
         *(f"--fault={f}" for f in faults)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    daemon: subprocess.Popen[str] | None = None
    scn = load_scene(scene, PRESET, scale, **scenario_overrides(platform_arguments(platform)))
    try:
        hello = read_json_line(sim, "the simulator", DAEMON_START_S)
        cfg_path = loopback_config(
            out, scn, hello["radar"]["connect"], (ins, _connect_link(hello["ins"][0]["connect"])),
            0, sections,
        )  # fmt: skip
        daemon = subprocess.Popen(
            [*py, "run", "--config", str(cfg_path), "--store", str(out / "run.zarr"),
             "--exit-when-idle", str(IDLE_EXIT_S)],
            stdout=subprocess.PIPE, text=True, env={**os.environ, **(daemon_env or {})},
        )  # fmt: skip
        read_json_line(daemon, "the daemon", DAEMON_START_S)
        _wait_for_both(sim, daemon)
    finally:
        for proc in (sim, daemon):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    truth = read_true_motion(out / "truth.json")
    if scn.clutter is None:
        return write_report(out / "run.zarr", out / "report", truth=truth)
    half = 0.5 * float(np.ptp(scn.clutter.x_m)) + PATCH_MARGIN_M
    return write_report(out / "run.zarr", out / "report", (half, half), truth)
