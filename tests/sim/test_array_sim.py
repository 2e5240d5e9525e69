"""The mimo-array preset's scenario and files: scale, roll, DEM input, streams."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.cli import main
from sarmoco.drivers.radar import RadarFileSource
from sarmoco.drivers.vita49 import VitaDecoder
from sarmoco.errors import ConfigError, DataFileError
from sarmoco.sim.array_echo import PAPER_DEM_RANGE_M
from sarmoco.sim.array_run import simulate_array, write_array_run
from sarmoco.sim.array_scenario import load_array_preset, read_dem


def test_full_scale_is_the_papers_table_1() -> None:
    scn = load_array_preset(1.0)
    r = scn.radar
    assert (r.carrier_hz, r.bandwidth_hz, r.sample_rate_hz, r.prf_hz) == (9.6e9, 150e6, 180e6, 200)
    assert r.pulse_width_s == pytest.approx(0.1e-6)
    assert (scn.layout.n_tx, scn.layout.n_rx, scn.epc_spacing_m) == (2, 80, 0.02)
    assert scn.layout.virtual_array()[1] == pytest.approx(0.02)
    assert (scn.speed_mps, scn.altitude_m) == (100.0, 200.0)
    assert math.degrees(scn.roll_rad) == pytest.approx(3.0)
    assert math.degrees(scn.max_look_rad) == pytest.approx(20.0)
    h = scn.terrain.height_m
    assert (float(h.min()), float(h.max())) == pytest.approx(PAPER_DEM_RANGE_M)
    # the scene is square: the 20 deg swath across, as long along track
    assert np.diff(scn.scene_north_m)[0] == pytest.approx(2 * scn.scene_half_width_m)
    assert scn.scene_half_width_m == pytest.approx(200 * math.tan(math.radians(20)))


def test_scale_cuts_the_strip_and_keeps_the_system() -> None:
    full, small = load_array_preset(1.0), load_array_preset(0.1)
    assert small.radar == full.radar and small.layout.n_channels == full.layout.n_channels
    assert np.diff(small.scene_north_m)[0] == pytest.approx(0.1 * np.diff(full.scene_north_m)[0])
    assert small.n_pulses < full.n_pulses / 5
    # the small terrain is the middle of the full one (same slopes)
    rows = small.terrain.height_m.shape[0]
    i0 = (full.terrain.height_m.shape[0] - rows) // 2
    mid = full.terrain.height_m[i0 : i0 + rows]
    assert np.abs(np.diff(small.terrain.height_m, axis=1)).max() == pytest.approx(
        np.abs(np.diff(mid, axis=1)).max(), rel=0.05
    )


def test_roll_series_varies_about_its_mean() -> None:
    scn = load_array_preset(0.1, roll_series=True, roll_deg=2.0, seed=4)
    t = np.linspace(0.0, 20.0, 4001)
    roll = np.degrees(scn.roll_rad_at(t))
    assert roll.mean() == pytest.approx(2.0, abs=0.3)
    assert 0.2 < roll.std() < 1.0
    assert load_array_preset(0.1).roll_series is None


def test_dem_file_is_read_and_bad_ones_are_refused(tmp_path: Path) -> None:
    good = tmp_path / "dem.npz"
    heights = 500.0 + np.add.outer(np.arange(400.0), np.arange(420.0)) * 0.05
    np.savez(good, height_m=heights, spacing_m=0.5)
    scn = load_array_preset(0.1, dem=good)
    assert scn.altitude_m == pytest.approx(200.0 + heights.mean())
    assert scn.terrain.height_m.min() >= heights.min()
    for name, arrays, message in (
        ("nospacing.npz", {"height_m": heights}, "no array 'spacing_m'"),
        ("flat.npz", {"height_m": heights[0], "spacing_m": 0.5}, "is not a 2-D grid"),
        ("coarse.npz", {"height_m": heights, "spacing_m": 30.0}, "is not the preset's terrain"),
        ("small.npz", {"height_m": heights[:20], "spacing_m": 0.5}, "smaller than"),
    ):
        np.savez(tmp_path / name, **arrays)
        with pytest.raises(DataFileError, match=message):
            load_array_preset(0.1, dem=tmp_path / name)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(DataFileError, match=r"cannot read as \.npz"):
        read_dem(tmp_path / "junk.npz")
    with pytest.raises(ConfigError, match=r"scenario\.scale"):
        load_array_preset(0.0)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--preset", "ku-vehicle", "--roll-deg", "2"], "sim --roll-deg: only the mimo-array"),
        (["--preset", "ku-vehicle", "--roll-series"], "sim --roll-series: only the mimo-array"),
        (["--preset", "mimo-array", "--serve"], "sim --serve: the mimo-array preset needs --radar"),
        (["--preset", "mimo-array", "--roll-deg", "50"], "--roll-deg: 50.0 is not a finite"),
    ],
)
def test_sim_refuses_array_arguments_out_of_place(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    if "--serve" not in argv:
        argv = [*argv, "--out", str(tmp_path / "out")]
    assert main(["sim", *argv]) == 2
    assert message in capsys.readouterr().err


def test_vrt_has_one_stream_per_pair(tmp_path: Path) -> None:
    scn = load_array_preset(0.02)
    run = simulate_array(scn, "ideal")
    write_array_run(run, tmp_path, payload="float32")
    decoder = VitaDecoder(scn.radar.n_samples, "float32")
    rows = np.empty((4096, scn.radar.n_samples), np.complex64)
    seen: list[tuple[int, int]] = []
    with RadarFileSource(tmp_path / "radar.vrt", decoder) as src:
        while not src.eof:
            packets = src.read_into(rows, 0.0)
            for p, row in zip(packets, rows, strict=False):
                seen.append((p.t_gps_ns, p.stream_id))
                k = int(np.searchsorted(run.t_ns, p.t_gps_ns))
                np.testing.assert_array_equal(row, run.echo[k, p.stream_id])
    assert len(seen) == run.t_ns.size * 160
    assert seen == [(int(t), c) for t in run.t_ns for c in range(160)]
