"""The live daemon as a real process on file links: ends of files, INS bytes, bad input.

The radar and INS come from ``sarmoco sim --out`` files as file links (the fixtures and
helpers of tests/daemon/test_daemon_process.py); each check reads the store back and
compares it with the files decoded by the drivers.

- File links read to their end are "finished", not failed: healthy, watchdog kept alive.
- A radar file longer than the echo ring is read at the processing pace, without drops.
- The INS bytes as received (MAVLink, SBG, SBG CAN logs) are recorded and decode again.
- A bad configuration exits with status 2 naming the key; garbage inserted into the
  ``.vrt`` and the ``.tlog`` is counted and skipped, the valid pulses are recorded.
"""

from __future__ import annotations

import json
import socket
import subprocess
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tomli_w

from sarmoco.app.simconfig import write_config
from sarmoco.daemon.config import Config, load_config
from sarmoco.daemon.links import open_ins
from sarmoco.drivers.samples import Sample
from sarmoco.sim.outfiles import NAV_FILES
from sarmoco.store.flags import PulseFlag, PushResult
from sarmoco.store.reader import RunStore, open_store
from tests.daemon.test_daemon_process import (
    N_PULSES,
    PY,
    WATCHDOG_USEC,
    Daemon,
    NotifyListener,
    SimFiles,
    check_pulses,
    daemon_config,
    decode_radar,
    free_port,
    http_get,
    nav_row,
    nav_rows,
    run_files_to_end,
    simulate_files,
    wait_finished,
    wait_focused,
    wait_received,
    wait_status,
)
from tests.daemon.test_daemon_process import sim as sim  # the module-scoped fixture


def test_file_links_that_end_are_finished_not_failed(sim: SimFiles, tmp_path: Path) -> None:
    """The ``.vrt`` and ``.tlog`` as file links, under a watchdog: once both are read to
    their end the daemon stays healthy (the links and the INS are "finished"), says so
    in /status and STATUS=, keeps sending WATCHDOG=1 (no restart loop) and exits 0. The
    store's INS bytes are the ``.tlog``'s MAVLink log (:func:`check_ins_bytes`; the SBG
    logs in :func:`test_ins_bytes_are_recorded_as_received`).

    The readers finish long before the pipeline has focused the file's pulses; the passes
    through that backlog may each take longer than half the watchdog period on a loaded
    machine (a fresh-clone CI run saw 2 pings in 2.5 s). The pings are counted from the
    first one after every pulse was recorded and none waits to be focused, when the
    daemon has nothing left to do."""
    port = free_port(socket.SOCK_STREAM)
    config = daemon_config(sim, tmp_path / "files.toml", status={"http_port": port})
    notify = NotifyListener(tmp_path / "notify.sock")
    d = Daemon(config, tmp_path / "files.zarr", notify.env(WATCHDOG_USEC))
    try:
        d.started()
        wait_finished(port)
        wait_received(port, N_PULSES)
        wait_focused(port)
        t_finished = notify.next_ping(after=notify.now())
        time.sleep(2.5)  # past the INS staleness limit (2 s) and several watchdog periods
        health = http_get(port, "/health")
        status = json.loads(http_get(port, "/status")[1])
        t_checked = notify.now()
        assert d.stop() == 0, d.log.read_text()
    finally:
        d.kill_if_running()
        notify.close()
    assert health == (200, "ok\n"), status
    links, ins = status["components"]["links"], status["components"]["ins"]
    assert links == {
        "ok": True,
        "detail": "ins: finished (end of file); radar: finished (end of file)",
    }
    assert ins["ok"] and ins["detail"].startswith("ins: finished (end of file), newest"), ins
    assert status["counters"]["pipeline_pulses_received"] == N_PULSES
    pings = [t for t in notify.pings() if t_finished <= t <= t_checked]
    assert len(pings) >= 3, notify.notes
    assert any("radar: finished (end of file)" in note for _, note in notify.notes)
    check_ins_bytes(open_store(d.store), load_config(config), sim.dir / NAV_FILES["mavlink"])


def test_a_file_longer_than_the_ring_is_read_at_the_processing_pace(tmp_path: Path) -> None:
    """A ``.vrt`` of 3000 pulses (the echo ring holds 1024) as the radar file link: the
    reader waits for room instead of dropping, so every pulse is recorded, none flagged.

    The ``.tlog`` of the same 17 s is read many times faster than the radar file: its
    samples are offered no further ahead of the pulses than the nav buffer keeps, and with
    no receive time (a file's read time is not the INS's send time), so every sample is
    accepted and every pulse leaves the aligner with navigation, as in a replay.
    """
    n_pulses = 3000
    simulate_files(tmp_path, n_pulses)
    table = tomllib.loads((tmp_path / "sarmoco.toml").read_text())
    table["status"] = {"http_port": free_port(socket.SOCK_STREAM)}
    table["autofocus"] = {"enabled": False}  # the pace of focusing does not matter here
    config = write_config(tmp_path / "long.toml", table)
    store, status = run_files_to_end(config, tmp_path / "long.zarr", table["status"]["http_port"])
    assert status["counters"]["pipeline_pulses_dropped_ring"] == 0
    assert store.committed("pulses") == n_pulses
    t_ns, echo = decode_radar(config, tmp_path / "radar.vrt", n_pulses)
    got = store.read("pulses", ["t_ns", "echo", "flags"])
    np.testing.assert_array_equal(got["t_ns"], t_ns)
    np.testing.assert_array_equal(got["echo"], echo)
    assert not (got["flags"] & np.uint32(PulseFlag.DROPPED_BEFORE)).any()
    nav_flags = np.uint32(PulseFlag.NAV_GAP | PulseFlag.NAV_TIMEOUT)
    assert not (got["flags"] & nav_flags).any(), "pulses released without navigation"
    results = store.read("nav", ["result"])["result"]
    assert results.size and (results == PushResult.ACCEPTED).all(), np.unique(results)


@pytest.mark.parametrize("protocol", ["sbg", "sbg-can"])
def test_ins_bytes_are_recorded_as_received(sim: SimFiles, tmp_path: Path, protocol: str) -> None:
    """Each simulated SBG log as the file link: :func:`check_ins_bytes` (the MAVLink
    ``.tlog`` in :func:`test_file_links_that_end_are_finished_not_failed`). Focusing plays
    no part: autofocus is off, so the daemon stops sooner."""
    log = sim.dir / NAV_FILES[protocol]
    port = free_port(socket.SOCK_STREAM)
    config = daemon_config(
        sim, tmp_path / "raw.toml",
        ins={"protocol": protocol, "link": str(log)}, status={"http_port": port},
        autofocus={"enabled": False},
    )  # fmt: skip
    store, _ = run_files_to_end(config, tmp_path / "raw.zarr", port)
    check_ins_bytes(store, load_config(config), log)


def check_ins_bytes(store: RunStore, cfg: Config, log: Path) -> None:
    """The store's ``ins_bytes``, written to a file with the log's suffix, is an INS log
    that decodes to the same samples as ``log`` (SBG: the very bytes), in the format the
    store names; their receive times are set and do not decrease."""
    protocol = cfg.ins.protocol
    fmt = {"mavlink": "tlog", "sbg": "sbgecom", "sbg-can": "candump"}[protocol]
    assert store.attrs["ins_raw"] == {"format": fmt}
    raw = store.ins_bytes()
    again = store.path.parent / f"again{log.suffix}"
    again.write_bytes(raw)
    if protocol == "sbg":
        assert raw == log.read_bytes()
    original = decode_all(cfg, log)
    assert len(original) > 100 and decode_all(cfg, again) == original
    rx = store.read("ins_raw", ["rx_ns"])["rx_ns"]
    assert rx.size > 0 and (rx > 0).all() and (np.diff(rx) >= 0).all()


def test_ins_bytes_not_recorded_when_switched_off(sim: SimFiles, tmp_path: Path) -> None:
    """recorder.raw_ins = false: INS samples recorded, no INS bytes, no ``ins_raw`` format."""
    port = free_port(socket.SOCK_STREAM)
    config = daemon_config(
        sim, tmp_path / "noraw.toml",
        ins={"protocol": "mavlink", "link": str(sim.dir / NAV_FILES["mavlink"])},
        status={"http_port": port}, recorder={"raw_ins": False}, autofocus={"enabled": False},
    )  # fmt: skip
    store, _ = run_files_to_end(config, tmp_path / "noraw.zarr", port)
    assert store.committed("nav") > 100
    assert "ins_raw" not in store.attrs and store.ins_bytes() == b""


def decode_all(cfg: Config, path: Path) -> list[Sample]:
    """Every sample the configured INS driver decodes from a log file."""
    out: list[Sample] = []
    with open_ins(cfg, str(path)) as src:
        while not src.eof:
            out += src.poll(0.0)
    return out


# -- bad configuration, garbage input -----------------------------------------------------


@pytest.mark.parametrize(
    ("section", "values", "key"),
    [
        ("radar", {"prf_hz": -3.0}, "radar.prf_hz"),
        ("recorder", {"fsync_s": 1.0}, "recorder.fsync_s"),
        ("ins", {"protocol": "nmea"}, "ins.protocol"),
        ("radar", {"range_gate_delay_s": 0.0}, "inside the nadir range geometry.height_m"),
    ],
    ids=["bound", "unknown-key", "not-allowed", "gate-inside-nadir"],
)
def test_bad_config_exits_2_naming_the_key(
    sim: SimFiles, tmp_path: Path, section: str, values: dict[str, Any], key: str
) -> None:
    table = {name: dict(v) for name, v in sim.table.items()}
    table.setdefault(section, {}).update(values)
    (tmp_path / "bad.toml").write_text(tomli_w.dumps(table))
    res = subprocess.run(
        [*PY, "run", "--config", str(tmp_path / "bad.toml"), "--store", str(tmp_path / "s.zarr")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert key in res.stderr and "Traceback" not in res.stderr, res.stderr
    assert not (tmp_path / "s.zarr").exists()


def test_status_port_in_use_exits_2_naming_the_key(sim: SimFiles, tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        config = daemon_config(
            sim, tmp_path / "busy.toml", status={"http_port": busy.getsockname()[1]}
        )
        res = subprocess.run(
            [*PY, "run", "--config", str(config), "--store", str(tmp_path / "s.zarr")],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert "status.http_port" in res.stderr and "Traceback" not in res.stderr, res.stderr


def with_garbage(data: bytes, cuts: list[int], rng: np.random.Generator) -> bytes:
    """``data`` with a burst of random bytes (1..600) inserted at each offset in ``cuts``."""
    parts, last = [], 0
    for cut in sorted(cuts):
        parts += [data[last:cut], rng.bytes(int(rng.integers(1, 600)))]
        last = cut
    return b"".join([*parts, data[last:], rng.bytes(4096)])


def test_garbage_in_the_radar_and_ins_files_is_counted_and_skipped(
    sim: SimFiles, tmp_path: Path
) -> None:
    rng = np.random.default_rng(5)
    sizes = np.cumsum([len(p) for p in sim.packets])
    between = [int(sizes[k]) for k in rng.choice(len(sim.packets) - 1, 25, replace=False)]
    (tmp_path / "radar.vrt").write_bytes(with_garbage(b"".join(sim.packets), between, rng))
    tlog = (sim.dir / "nav.tlog").read_bytes()
    anywhere = rng.choice(len(tlog), 25, replace=False).tolist()
    (tmp_path / "nav.tlog").write_bytes(with_garbage(tlog, anywhere, rng))
    port = free_port(socket.SOCK_STREAM)
    config = daemon_config(
        sim, tmp_path / "garbage.toml",
        radar={"link": str(tmp_path / "radar.vrt")},
        ins={"link": str(tmp_path / "nav.tlog")},
        status={"http_port": port},
    )  # fmt: skip
    d = Daemon(config, tmp_path / "garbage.zarr")
    try:
        d.started()
        wait_status(port, "counters", "pipeline_pulses_received", N_PULSES)
        time.sleep(0.5)  # the INS log is read to its end meanwhile
        status = json.loads(http_get(port, "/status")[1])
        assert d.stop() == 0, d.log.read_text()
    finally:
        d.kill_if_running()
    c = status["counters"]
    assert c["radar_frames"] == len(sim.packets)  # every valid packet, context included
    assert c["radar_skipped_bytes"] > 0
    assert c["ins_crc_errors"] + c["ins_parse_errors"] + c["ins_skipped_bytes"] > 0, c
    store = open_store(d.store)
    assert store.attrs["complete"] is True
    assert check_pulses(store, sim) == N_PULSES
    rows = nav_rows(store)
    assert len(rows) >= 0.9 * len(sim.nav)
    expected = iter([nav_row(s) for s in sim.nav])
    assert all(row in expected for row in rows)  # the files' samples, in order, some lost
