"""A 10 s INS silence through the real processes: ``sarmoco sim --serve`` into ``sarmoco run``
over MAVLink/UDP and VITA/UDP, ku-vehicle x0.03 (232 samples, 175 Hz PRF) played for
14.5 s (``sarmoco sim --pulses``: the platform flies on along the track past the targets,
whose aperture is the first 2.63 s), ``/status`` polled every 0.1 s while the daemon runs.

The INS sends nothing from 3.0 s to 13.0 s after the first pulse (``ins-dropout=3:10``,
issue 12's longest dropout). Checked:

- every pulse sent is in the store (complete), and the pulses of the silence, and only
  they, are flagged ``NAV_TIMEOUT`` or ``NAV_GAP`` and not focused: the store's focused
  count leaves them out, and the image tiles whose whole aperture fell in the silence
  are empty (no echo backprojected) while every tile before and after it holds echo;
- ``/status`` says the INS is unhealthy, its newest sample older than
  :data:`~sarmoco.daemon.runner.INS_STALE_S` and growing to about 10 s, during the silence,
  and healthy again (a fresh sample) after it; the daemon stays up and exits 0;
- the pulses after the silence are focused (their tiles hold echo), and the target
  (imaged before the silence) keeps its azimuth PSLR within 1 dB of the sinc's.

The targets are all imaged before the silence: a preset flight cannot place one after it.
"""

from __future__ import annotations

import json
import re
import threading
import time
from typing import Any

import numpy as np
import pytest

from sarmoco.app.demo import run_loopback
from sarmoco.daemon.flags import NAV_UNUSABLE
from sarmoco.daemon.runner import INS_STALE_S
from sarmoco.daemon.store import open_store
from sarmoco.sim.scenario import load_preset
from tests.daemon.test_faults_can_bus import _status
from tests.daemon.test_faults_ins_link import _free_tcp_port
from tests.daemon.test_faults_wire import SINC_PSLR_DB

SCALE = 0.03
FLIGHT_S = 14.5
"""Seconds of pulses played."""
SILENCE_S = (3.0, 10.0)
"""INS silence: start after the first pulse, and length, s."""
EDGE_S = 0.05
"""Pulses this close to the silence's ends may go either way (the INS samples at 200 Hz), s."""
AGE = re.compile(r"newest sample ([0-9.]+|inf) s old")


def test_ten_second_ins_silence(tmp_path_factory: pytest.TempPathFactory) -> None:
    out = tmp_path_factory.mktemp("ins_silence_10s")
    port = _free_tcp_port()
    n_pulses = round(FLIGHT_S * load_preset("ku-vehicle", SCALE).radar.prf_hz)
    seen: list[dict[str, Any]] = []
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            doc = _status(port)
            if doc is not None:
                seen.append(doc)
            time.sleep(0.1)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        summary = run_loopback(
            out, SCALE, faults=(f"ins-dropout={SILENCE_S[0]}:{SILENCE_S[1]}",),
            pulses=n_pulses, status={"http_port": port},
        )  # fmt: skip
    finally:
        done.set()
        watcher.join()
    store = open_store(out / "run.zarr")
    assert store.attrs["complete"]
    truth = json.loads((out / "truth.json").read_text())
    sent_ns = np.asarray(truth["pulses"]["t_ns"]) + truth["wire"]["shift_ns"]
    got = store.read("pulses", ["t_ns", "flags"])
    t_s = (got["t_ns"] - sent_ns[0]) / 1e9  # from the first pulse
    flagged = (got["flags"] & np.uint32(NAV_UNUSABLE)) != 0
    start, end = SILENCE_S[0], sum(SILENCE_S)
    inside = (t_s >= start + EDGE_S) & (t_s < end - EDGE_S)
    outside = (t_s < start - EDGE_S) | (t_s >= end + EDGE_S)
    metrics = store.attrs["metrics"]
    tiles = [store.image(i) for i in range(store.n_images)]
    tile_t1_s = np.array([(a["t1_ns"] - sent_ns[0]) / 1e9 for _, a in tiles])
    tile_echo = np.array([bool(np.any(im.data)) for im, _ in tiles])
    ins = [(d["components"]["ins"], d["healthy"]) for d in seen if "ins" in d["components"]]
    ages = [float(m[1]) if (m := AGE.search(c["detail"])) else np.nan for c, _ in ins]
    stale = [i for i, a in enumerate(ages) if INS_STALE_S < a < np.inf]  # inf: before the first
    pslr = summary["image"]["points"][0]["pslr_az_db"]
    print(f"INS silent {SILENCE_S[1]} s from {start} s, {FLIGHT_S} s flight: {t_s.size} of "
          f"{sent_ns.size} pulses stored, {flagged.sum()} flagged ({flagged[inside].sum()} of "
          f"{inside.sum()} inside, {flagged[outside].sum()} outside; span "
          f"{t_s[flagged].min() if flagged.any() else None} .. "
          f"{t_s[flagged].max() if flagged.any() else None} s), "
          f"{metrics['pulses_processed']} focused; tiles with echo by aperture end (s): "
          f"{[(round(float(t), 2), bool(e)) for t, e in zip(tile_t1_s, tile_echo, strict=True)]}; "
          f"/status: {len(stale)} of {len(ins)} reads stale, ages "
          f"{ages[stale[0]] if stale else None} .. {max(ages[i] for i in stale) if stale else None}"
          f" s, last {ins[-1]}; brightest target azimuth PSLR {pslr:.2f} dB")  # fmt: skip
    # every pulse stored; the silence's pulses flagged, nothing else
    assert t_s.size == sent_ns.size == n_pulses
    assert np.array_equal(np.sort(got["t_ns"]), np.sort(sent_ns))
    assert flagged[inside].all() and not flagged[outside].any()
    assert metrics["pulses_nav_flagged"] == flagged.sum()
    assert metrics["pulses_processed"] == t_s.size - flagged.sum()  # flagged: not focused
    # tiles: empty where every pulse of their aperture was silent, echo before and after
    silent = ~tile_echo
    assert silent.sum() >= 0.6 * SILENCE_S[1] * 17.5 / 10.0, silent.sum()  # 10 m tiles, 17.5 m/s
    assert ((tile_t1_s[silent] > start) & (tile_t1_s[silent] <= end)).all()
    assert tile_echo[(tile_t1_s <= start) | (tile_t1_s > end + EDGE_S)].all()
    assert (tile_t1_s > end + 1.0).any()  # tiles whose aperture is mostly after the silence
    # /status: stale during the silence, healthy after; the daemon stayed up
    assert stale and all(not c["ok"] and not healthy for c, healthy in (ins[i] for i in stale))
    # stale from early in the silence until late in it (read between processing passes)
    assert ages[stale[0]] < INS_STALE_S + 1.5, ages[stale[0]]
    assert SILENCE_S[1] - 2.0 < max(ages[i] for i in stale) < SILENCE_S[1] + 1.0
    assert stale == list(range(stale[0], stale[-1] + 1))  # one stretch
    after = ins[stale[-1] + 1 :]
    assert after and after[0][0]["ok"] and ages[stale[-1] + 1] < 1.0, after[:1]
    assert pslr <= SINC_PSLR_DB + 1.0, pslr
