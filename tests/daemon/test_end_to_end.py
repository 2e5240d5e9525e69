"""End to end, real processes on loopback: ``sarmoco sim --serve`` → ``sarmoco run``.

Each link combination of the issue plays a scaled ku-vehicle scenario (turbulent
cross-track motion, tactical INS) in real time; the daemon focuses and records it,
stops cleanly on SIGTERM, and the store's image must show every point target
focused to the autofocus's acceptance thresholds (PSLR ≤ -12.5 dB, IRW ≤ 1.1 × theory).
The MAVLink run is then replayed, from its store (same image to float tolerance) and
from the simulator's raw ``.vrt`` + ``.tlog`` files.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.demo import run_loopback
from sarmoco.daemon.config import load_config
from sarmoco.daemon.runner import replay_store
from sarmoco.products.report import bright_points, strip
from sarmoco.store.reader import open_store
from tests.daemon.same_images import assert_same_images

SCALE = 0.1
LINKS = [("mavlink", "udp"), ("sbg", "tcp"), ("sbg-can", "udp")]


def targets_in_image(out: Path) -> list[tuple[float, float, float]]:
    """Truth targets in the store's imaging frame: (x along track, y ground range, slant r).

    The frame is the one the daemon recorded (``reference_track``: its start time and
    axes from the INS); the origin is the true APC at that time.
    """
    truth = json.loads((out / "truth.json").read_text())
    track = open_store(out / "run.zarr").attrs["reference_track"]
    t_wire = np.asarray(truth["pulses"]["t_ns"], dtype=np.int64) + truth["wire"]["shift_ns"]
    first = int(np.searchsorted(t_wire, track["t0_ns"]))
    assert t_wire[first] == track["t0_ns"]
    apc0 = np.asarray(truth["pulses"]["apc_ned"][first])
    x_hat, y_hat = np.asarray(track["x_hat_ned"]), np.asarray(track["y_hat_ned"])
    out_list = []
    for tgt in truth["targets"]:
        d = np.asarray(tgt["pos_ned"]) - apc0
        out_list.append((float(d @ x_hat), float(d @ y_hat), float(np.linalg.norm(d))))
    return out_list


def store_points(store_path: Path) -> list[dict[str, float]]:
    """The bright points of a store's image, as the report's ``image.points`` gives them
    (without the report's pictures and re-focused comparison)."""
    image = strip(open_store(store_path))
    assert image is not None, f"{store_path} holds no image"
    return bright_points(image)


def assert_focused(
    out: Path, points: list[dict[str, float]], near_m: float = 0.5
) -> list[dict[str, float]]:
    """Every truth target is found focused at its place (within ``near_m``, m) among the
    ``points`` (the report's ``image.points``).

    Returns the point of each target (in the truth's order).
    """
    scn = json.loads((out / "truth.json").read_text())["scenario"]
    cell = 299_792_458.0 / (2 * scn["radar"]["bandwidth_hz"])
    lam = 299_792_458.0 / scn["radar"]["carrier_hz"]
    irw_az = 0.886 * lam / (4 * math.sin(scn["integration_angle_rad"] / 2))
    found = []
    for x, y, r in targets_in_image(out):
        near = [p for p in points if math.hypot(p["x_m"] - x, p["y_m"] - y) < near_m]
        assert near, f"target ({x:.2f}, {y:.2f}) not found among {points}"
        p = near[0]
        assert p["pslr_az_db"] <= -12.5 and p["pslr_rg_db"] <= -12.5, p
        assert p["irw_az_m"] <= 1.1 * irw_az, p
        assert p["irw_rg_m"] <= 1.1 * 0.886 * cell * r / y, p
        found.append(p)
    return found


@pytest.fixture(scope="module")
def live_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    runs = {}
    for ins, radar in LINKS:
        out = tmp_path_factory.mktemp(f"{ins}-{radar}")
        run_loopback(out, SCALE, ins=ins, radar=radar)
        runs[ins] = out
    return runs


@pytest.mark.parametrize(("ins", "radar"), LINKS, ids=[f"{i}+vita-{r}" for i, r in LINKS])
def test_live_run_focuses_and_records(live_runs: dict[str, Path], ins: str, radar: str) -> None:
    out = live_runs[ins]
    store = open_store(out / "run.zarr")
    assert store.attrs["complete"]
    n_sent = len(json.loads((out / "truth.json").read_text())["pulses"]["t_ns"])
    run = store.attrs["metrics"]
    assert store.committed("pulses") == n_sent
    assert run["pulses_processed"] + run["pulses_nav_flagged"] == n_sent
    assert run["pulses_nav_flagged"] <= 0.05 * n_sent
    assert store.committed("nav") > 0 and store.n_images > 0
    summary = json.loads((out / "report" / "report.json").read_text())
    found = assert_focused(out, summary["image"]["points"])
    print(  # the README's figures (pytest -s)
        f"\n{ins}+vita-{radar}: azimuth PSLR "
        + " / ".join(f"{p['pslr_az_db']:.2f}" for p in found)
        + " dB, range PSLR "
        + " / ".join(f"{p['pslr_rg_db']:.2f}" for p in found)
        + " dB, azimuth IRW "
        + " / ".join(f"{p['irw_az_m']:.3f}" for p in found)
        + " m"
    )


LIVE_HEADING = "[mocomp]\nheading_window_s = 0.0\n"
"""What a replay adds to a live run's configuration to lay its grid as the live run did:
along the first processing block's velocity (a replay would follow 4 s of the INS log)."""


def test_replay_of_store_reproduces_live_image(live_runs: dict[str, Path], tmp_path: Path) -> None:
    live = live_runs["mavlink"]
    config = tmp_path / "sarmoco.toml"
    config.write_text((live / "sarmoco.toml").read_text() + LIVE_HEADING)
    replay_store(load_config(config), live / "run.zarr", tmp_path / "replay.zarr", progress=False)
    assert_same_images(open_store(live / "run.zarr"), open_store(tmp_path / "replay.zarr"))


def test_replay_of_raw_files_gives_the_same_image(
    live_runs: dict[str, Path], tmp_path: Path
) -> None:
    """`sarmoco sim --out` files (same scenario and seeds) replayed through `sarmoco replay`."""
    sim = tmp_path / "sim"
    subprocess.run(
        [sys.executable, "-m", "sarmoco", "sim", "--preset", "ku-vehicle", "--scale",
         str(SCALE), "--motion", "turbulence", "--motion-seed", "1", "--ins-grade",
         "tactical", "--out", str(sim)],
        check=True, capture_output=True,
    )  # fmt: skip
    with (sim / "sarmoco.toml").open("a") as config:
        config.write(LIVE_HEADING)
    subprocess.run(
        [sys.executable, "-m", "sarmoco", "replay", "--config", str(sim / "sarmoco.toml"),
         "--radar", str(sim / "radar.vrt"), "--nav", str(sim / "nav.tlog"),
         "--out", str(tmp_path / "replay.zarr"), "--quiet"],
        check=True, capture_output=True,
    )  # fmt: skip
    points = store_points(tmp_path / "replay.zarr")
    live = json.loads((live_runs["mavlink"] / "report" / "report.json").read_text())
    for p in live["image"]["points"][:3]:
        same = [
            q for q in points
            if abs(q["y_m"] - p["y_m"]) < 0.05 and abs(q["x_m"] - p["x_m"]) < 0.5
        ]  # fmt: skip
        assert same, (p, points)
        assert abs(same[0]["irw_az_m"] - p["irw_az_m"]) < 0.02
        assert abs(same[0]["irw_rg_m"] - p["irw_rg_m"]) < 0.005
        assert same[0]["pslr_az_db"] <= -12.5 and same[0]["pslr_rg_db"] <= -12.5
