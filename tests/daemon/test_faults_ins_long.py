"""A 10 s INS silence through the real processes: ``sarmoco sim --serve`` into ``sarmoco run``
over MAVLink/UDP and VITA/UDP, ku-vehicle x0.03 (232 samples, 175 Hz PRF) with 11.5 s of
straight approach before the targets' aperture (``sarmoco sim --approach-s``: 14.1 s of
pulses, the targets in the beam over the last 2.6 s), ``/status`` polled every 0.1 s while
the daemon runs. One run serves both tests.

The INS sends nothing from 1.0 s to 11.0 s after the first pulse (``ins-dropout=1:10``),
0.5 s before the targets come into the beam. Checked:

- every pulse sent is in the store (complete), and the pulses of the silence, and only
  they, are flagged ``NAV_TIMEOUT`` or ``NAV_GAP`` and not focused: the store's focused
  count leaves them out, and the image tiles whose whole aperture fell in the silence
  are empty (no echo backprojected) while every tile before and after it holds echo;
- ``/status`` says the INS is unhealthy, its newest sample older than
  :data:`~sarmoco.daemon.runner.INS_STALE_S` and growing to about 10 s, during the silence,
  and healthy again (a fresh sample) after it; the daemon stays up and exits 0;
- the targets, imaged after the silence, are focused: azimuth PSLR within 1 dB of the
  sinc's, and azimuth IRW within 10 % of theory (0.177 m). The daemon's segment after the
  silence used to start inside it, its track along the placeholder velocity held from the
  silence's start (-14.2 mrad heading); the pixels take the pulses within half the beam
  plus 0.3° (5.2 mrad) of the track's broadside, and the simulator's beam stays on the
  nominal heading (0 mrad): 9 of the 50 mrad aperture were cut, IRW 0.205-0.214 m =
  1.16-1.21 x. Now a segment starts at the first pulse with navigation after the silence,
  along the velocity flown after it (:mod:`sarmoco.processing.segments`): 0.179-0.180 m.

Marked ``bench`` (``pytest -m bench tests/daemon/test_faults_ins_long.py``): the run takes
59-65 s on the 2 shared cores at load 3.5-4.7 (14.1 s of flight, the rest starting the
simulator and daemon, draining and the report), over the suite's 40 s for one live test.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sarmoco.app.demo import run_loopback
from sarmoco.daemon.runner import INS_STALE_S
from sarmoco.products.report import ReportSummary
from sarmoco.store.flags import NAV_UNUSABLE
from sarmoco.store.reader import open_store
from tests.daemon.statuswatch import watching_status
from tests.daemon.test_faults_ins_link import _free_tcp_port
from tests.daemon.test_faults_wire import SINC_PSLR_DB

SCALE = 0.03
APPROACH_S = 11.5
"""Straight flight before the targets' aperture, s."""
SILENCE_S = (1.0, 10.0)
"""INS silence: start after the first pulse, and length, s."""
EDGE_S = 0.05
"""Pulses this close to the silence's ends may go either way (the INS samples at 200 Hz), s."""
AGE = re.compile(r"newest sample ([0-9.]+|inf) s old")

pytestmark = pytest.mark.bench


@dataclass(frozen=True)
class _Run:
    out: Path
    summary: ReportSummary
    status: list[dict[str, Any]]
    """The ``/status`` documents read while the daemon ran, in order."""


@pytest.fixture(scope="module")
def silence_run(tmp_path_factory: pytest.TempPathFactory) -> _Run:
    """The flight with the 10 s INS silence, played into the daemon once for the module."""
    out = tmp_path_factory.mktemp("ins_silence_10s")
    port = _free_tcp_port()
    with watching_status(port, 0.1) as seen:
        summary = run_loopback(
            out, SCALE, platform=("--approach-s", str(APPROACH_S)),
            faults=(f"ins-dropout={SILENCE_S[0]}:{SILENCE_S[1]}",), status={"http_port": port},
        )  # fmt: skip
    return _Run(out, summary, seen)


def test_ten_second_ins_silence(silence_run: _Run) -> None:
    out, seen = silence_run.out, silence_run.status
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
    points = silence_run.summary.image.points
    targets = [p for p in points if p["peak_db"] > -6.0]  # the bright ones, not noise peaks
    print(f"INS silent {SILENCE_S[1]} s from {start} s, {t_s.size and t_s.max():.2f} s flight: "
          f"{t_s.size} of {sent_ns.size} pulses stored, {flagged.sum()} flagged "
          f"({flagged[inside].sum()} of {inside.sum()} inside, {flagged[outside].sum()} outside; "
          f"span {t_s[flagged].min() if flagged.any() else None} .. "
          f"{t_s[flagged].max() if flagged.any() else None} s), "
          f"{metrics['pulses_processed']} focused; tiles with echo by aperture end (s): "
          f"{[(round(float(t), 2), bool(e)) for t, e in zip(tile_t1_s, tile_echo, strict=True)]}; "
          f"/status: {len(stale)} of {len(ins)} reads stale, ages "
          f"{ages[stale[0]] if stale else None} .. {max(ages[i] for i in stale) if stale else None}"
          f" s, last {ins[-1]}; targets after the silence (azimuth PSLR dB, IRW m): "
          f"{[(round(p['pslr_az_db'], 2), round(p['irw_az_m'], 3)) for p in targets]}")  # fmt: skip
    # every pulse stored; the silence's pulses flagged, nothing else
    assert t_s.size == sent_ns.size
    assert np.array_equal(np.sort(got["t_ns"]), np.sort(sent_ns))
    assert flagged[inside].all() and not flagged[outside].any()
    assert metrics["pulses_nav_flagged"] == flagged.sum()
    assert metrics["pulses_processed"] == t_s.size - flagged.sum()  # flagged: not focused
    # tiles: empty where every pulse of their aperture was silent, echo before and after
    silent = ~tile_echo
    assert silent.sum() >= 0.6 * SILENCE_S[1] * 17.5 / 10.0, silent.sum()  # 10 m tiles, 17.5 m/s
    assert ((tile_t1_s[silent] > start) & (tile_t1_s[silent] <= end)).all()
    assert tile_echo[(tile_t1_s <= start) | (tile_t1_s > end + EDGE_S)].all()
    # /status: stale during the silence, healthy after; the daemon stayed up
    assert stale and all(not c["ok"] and not healthy for c, healthy in (ins[i] for i in stale))
    # stale from early in the silence until late in it (read between processing passes)
    assert ages[stale[0]] < INS_STALE_S + 1.5, ages[stale[0]]
    assert SILENCE_S[1] - 2.0 < max(ages[i] for i in stale) < SILENCE_S[1] + 1.0
    assert stale == list(range(stale[0], stale[-1] + 1))  # one stretch
    after = ins[stale[-1] + 1 :]
    assert after and after[0][0]["ok"] and ages[stale[-1] + 1] < 1.0, after[:1]
    # the targets, whose aperture is all after the silence, are focused
    assert targets and all(p["pslr_az_db"] <= SINC_PSLR_DB + 1.0 for p in targets), points


def test_focus_resolution_after_ten_second_ins_silence(silence_run: _Run) -> None:
    scn = json.loads((silence_run.out / "truth.json").read_text())["scenario"]
    lam = 299_792_458.0 / scn["radar"]["carrier_hz"]
    irw_az = 0.886 * lam / (4 * math.sin(scn["integration_angle_rad"] / 2))
    targets = [p for p in silence_run.summary.image.points if p["peak_db"] > -6.0]
    print(f"after the 10 s silence: azimuth IRW {[p['irw_az_m'] for p in targets]} m, "
          f"theory {irw_az:.3f} m")  # fmt: skip
    assert targets and all(p["irw_az_m"] <= 1.1 * irw_az for p in targets), targets
