"""The operator's live page in a real headless Chromium during a live run, and the extended
demo scene that run flies over.

One run (module fixture): ``sarmoco sim --serve --scene extended`` into ``sarmoco run`` on
loopback (:func:`sarmoco.app.demo.run_loopback`, the demo's own path), the status endpoint
on a known port. While it flies, Chromium (the distribution's package; ``.ci/run``
installs it) loads ``http://127.0.0.1:<port>/``, and every half second the test calls
the page's own ``tick()`` (what its timer calls every 2 s: a run's tiles can all come
within 2 s) and waits for the strip ``<img>`` to load; each time it shows a new picture,
its pixels' hash, the tile count the page shows and a screenshot are kept. Screenshots
go to ``$SARMOCO_TEST_ARTEFACTS`` (default: the test's temporary folder); the last is the
README's ``docs/img/live-page.png``.

The scene is then measured: the focused intensity, averaged over 1 m cells (5 x 5
resolution cells), is correlated with the scene's reflectivity map for the three panels
of the report's comparison (raw, INS only, INS + autofocus).
"""

from __future__ import annotations

import io
import os
import socket
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image as PilImage

from sarmoco.app.demo import run_loopback
from sarmoco.products.report import PANELS, focus_comparison
from sarmoco.sim.extended import extended_scenario
from sarmoco.sim.scenario import Scenario
from sarmoco.store.reader import open_store
from tests.app.headless import HeadlessChromium, chromium_or_skip
from tests.daemon.test_daemon_process import free_port
from tests.daemon.test_end_to_end import SCALE, targets_in_image

RUN_TIMEOUT_S = 400.0
"""Longest the live run (simulation, focusing, report) may take, s."""

POLL_S = 0.25
"""How often the page is refreshed and looked at, s."""

CELL_M = 1.0
"""Side of the cells the intensity and the reflectivity are averaged over, m."""

SCENE_CORRELATION_MIN = 0.85
"""Least correlation of a focused panel with the reflectivity (measured 0.92..0.96)."""

UNFOCUSED_CORRELATION_MAX = 0.3
"""Most correlation without motion compensation (measured 0.05: the scene is not seen)."""

REFLECTOR_CLEARANCE_M = 1.5
"""Cells this close to a corner reflector are left out of the correlation (its sidelobes)."""

STRIP_STATE = """(async () => {
  const s = document.getElementById("strip");
  if (!s) return null;
  const loaded = new Promise(done => { s.onload = s.onerror = done; setTimeout(done, 3000); });
  s.src = "tiles/latest.png?" + Date.now();
  await Promise.all([loaded, status().catch(() => {})]);
  if (!s.complete || !s.naturalWidth) return null;
  const c = document.createElement("canvas");
  c.width = s.naturalWidth; c.height = s.naturalHeight;
  const g = c.getContext("2d");
  g.drawImage(s, 0, 0);
  const d = g.getImageData(0, 0, c.width, c.height).data;
  let h = 0, lit = 0;
  for (let i = 0; i < d.length; i += 4) { h = (Math.imul(h, 31) + d[i]) >>> 0; lit += d[i] > 0; }
  const r = s.getBoundingClientRect();
  const run = document.getElementById("run").innerText;
  return {width: c.width, height: c.height, hash: h, lit: lit, run: run,
          health: document.getElementById("health").innerText,
          rect: {x: r.x, y: r.y, width: r.width, height: r.height}};
})()"""
"""JavaScript: refresh the page as its timer's ``tick()`` does (the strip and the page's
``status()``), wait for both, and describe the strip as drawn (null when it did not load)."""


def artefact_dir(tmp_path: Path) -> Path:
    """``$SARMOCO_TEST_ARTEFACTS`` (created), or ``tmp_path``."""
    folder = Path(os.environ.get("SARMOCO_TEST_ARTEFACTS", tmp_path))
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def page_up(port: int) -> bool:
    """Whether ``GET /`` answers 200 now."""
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2) as resp:
            return int(resp.status) == 200
    except (urllib.error.URLError, OSError):
        return False


@pytest.fixture(scope="module")
def browsed_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The extended-scene live run, watched in Chromium: ``out``, ``states``, ``shots``."""
    chromium = chromium_or_skip()
    out = tmp_path_factory.mktemp("extended")
    shots_dir = artefact_dir(tmp_path_factory.mktemp("artefacts"))
    port = free_port(socket.SOCK_STREAM)
    errors: list[BaseException] = []

    def fly() -> None:
        try:
            # the autofocus releases nothing before its pin window (2 s by default) is
            # covered: with 0.5 s the 4 s flight releases tiles over its last 2.5 s, not in
            # a burst at its end that the page may show as one strip; 5 m tiles (not 10)
            # give the page twice as many to follow, and it renders up to 4 times a second
            # (1 by default: the tiles of a quiet machine's run can all come within 2 s)
            run_loopback(
                out, SCALE, scene="extended",
                autofocus={"pin_window_s": 0.5}, imaging={"tile_length_m": 5.0},
                status={"http_port": port, "live_render_interval_s": 0.25},
            )  # fmt: skip
        except BaseException as exc:  # handed to the test
            errors.append(exc)

    states: list[dict[str, Any]] = []
    shots: list[tuple[Path, Path]] = []
    # Chromium is started before the flight: its start (seconds on a loaded machine) once
    # took the first half of the 4 s flight, and the first strip drawn then held every tile
    with HeadlessChromium(chromium, 1100, 950) as browser:
        thread = threading.Thread(target=fly, name="live-run")
        thread.start()
        started = time.monotonic()
        deadline = started + RUN_TIMEOUT_S
        try:
            while thread.is_alive() and not page_up(port) and time.monotonic() < deadline:
                time.sleep(0.1)
            browser.navigate(f"http://127.0.0.1:{port}/")
            while thread.is_alive() and time.monotonic() < deadline:
                try:
                    state = browser.evaluate(STRIP_STATE)
                except RuntimeError:  # the daemon went away, or a slow answer under load
                    if page_up(port):
                        continue
                    break
                if state and (not states or state["hash"] != states[-1]["hash"]):
                    n = len(states)
                    page = browser.screenshot(shots_dir / f"live-page-{n}.png")
                    strip = browser.screenshot(shots_dir / f"strip-{n}.png", clip=state["rect"])
                    state["t_s"] = round(time.monotonic() - started, 2)
                    states.append(state)
                    shots.append((page, strip))
                time.sleep(POLL_S)
        finally:
            thread.join(timeout=max(deadline - time.monotonic(), 1.0))
    assert not thread.is_alive(), "the live run did not finish"
    if errors:
        raise errors[0]
    return {"out": out, "states": states, "shots": shots}


def test_live_page_shows_tiles_as_they_come(browsed_run: dict[str, Any]) -> None:
    states, shots = browsed_run["states"], browsed_run["shots"]
    print(f"live page: {len(states)} strips seen; screenshots in {shots[-1][0].parent}"
          if shots else "live page: no strip seen")  # fmt: skip
    print("strips (s after the run's start, page text):",
          [(s["t_s"], " ".join(s["run"].split())) for s in states])  # fmt: skip
    assert len(states) >= 2, f"the strip did not update during the run: {states}"
    for state in states:
        assert state["width"] > 10 and state["height"] > 10 and state["lit"] > 0, state
        assert "tiles" in state["run"] and "links" in state["health"], state
    tiles = [int(line.split()[-1]) for s in states for line in s["run"].splitlines()
             if line.startswith("tiles")]  # fmt: skip
    assert tiles and tiles[-1] >= 2 and tiles[-1] > tiles[0], tiles  # it followed new tiles
    first, last = (np.asarray(PilImage.open(io.BytesIO(s.read_bytes())).convert("L"), dtype=float)
                   for s in (shots[0][1], shots[-1][1]))  # fmt: skip
    # a strip of fewer than four tiles is drawn with another aspect (another height); of the
    # same size, the pixels drawn must differ
    assert first.shape != last.shape or float(np.mean(np.abs(first - last))) > 1.0
    page = PilImage.open(shots[-1][0])
    assert page.format == "PNG" and page.size == (1100, 950)


def cell_means(
    values: np.ndarray, axis0_m: np.ndarray, axis1_m: np.ndarray, edges0: np.ndarray,
    edges1: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Mean of ``values`` (on the axes, m) in each cell of ``edges0`` x ``edges1`` (m)."""
    i = np.digitize(axis0_m, edges0) - 1
    j = np.digitize(axis1_m, edges1) - 1
    shape = (edges0.size - 1, edges1.size - 1)
    ok0, ok1 = (i >= 0) & (i < shape[0]), (j >= 0) & (j < shape[1])
    sums, counts = np.zeros(shape), np.zeros(shape)
    ii, jj = np.meshgrid(i[ok0], j[ok1], indexing="ij")
    np.add.at(sums, (ii, jj), values[np.ix_(ok0, ok1)])
    np.add.at(counts, (ii, jj), 1.0)
    return sums / np.maximum(counts, 1.0)


def scene_correlations(out: Path, scn: Scenario) -> tuple[dict[str, float], tuple[float, float]]:
    """Correlation of each comparison panel's 1 m-cell intensity with the reflectivity.

    The scene is registered on its central reflector as the focused image places it (the
    image sits where the INS puts it, up to the INS's absolute position error).

    Returns
    -------
    correlations : dict of str to float
        Panel title to correlation coefficient.
    offset_m : tuple of float
        Where the image put the central reflector minus where the truth has it (x, y), m.
    """
    clutter = scn.clutter
    assert clutter is not None
    half = 0.5 * float(np.ptp(clutter.x_m)) + 1.0
    panels, _ = focus_comparison(open_store(out / "run.zarr"), (half, half))
    focused = panels[PANELS[2]]
    i, j = np.unravel_index(int(np.argmax(np.abs(focused.data))), focused.data.shape)
    reflectors = targets_in_image(out)  # the central one first, the brightest
    offset = (float(focused.axis0_m[i]) - reflectors[0][0],
              float(focused.axis1_m[j]) - reflectors[0][1])  # fmt: skip
    cx = reflectors[0][0] + offset[0] + clutter.x_m
    cy = reflectors[0][1] + offset[1] + clutter.y_m - scn.scene_center_ned[1]
    edges0 = np.arange(cx[0], cx[-1], CELL_M)
    edges1 = np.arange(cy[0], cy[-1], CELL_M)
    truth = cell_means(clutter.reflectivity, cx, cy, edges0, edges1)
    m0, m1 = np.meshgrid(0.5 * (edges0[1:] + edges0[:-1]), 0.5 * (edges1[1:] + edges1[:-1]),
                         indexing="ij")  # fmt: skip
    keep = np.ones(truth.shape, dtype=bool)
    for x, y, _ in reflectors:
        keep &= np.hypot(m0 - x - offset[0], m1 - y - offset[1]) > REFLECTOR_CLEARANCE_M
    result = {}
    for name, im in panels.items():
        power = cell_means(np.abs(im.data) ** 2, im.axis0_m, im.axis1_m, edges0, edges1)
        result[name] = float(np.corrcoef(power[keep], truth[keep])[0, 1])
    return result, offset


def test_extended_scene_is_recognisable(browsed_run: dict[str, Any]) -> None:
    """The focused terrain matches its reflectivity map; without motion compensation not."""
    corr, offset = scene_correlations(browsed_run["out"], extended_scenario("ku-vehicle", SCALE))
    print(f"scene placed ({offset[0]:+.2f}, {offset[1]:+.2f}) m from the truth; correlation "
          "with the reflectivity (1 m cells): "
          + ", ".join(f"{k} {v:.3f}" for k, v in corr.items()))  # fmt: skip
    raw, ins, af = (corr[name] for name in PANELS)
    assert ins >= SCENE_CORRELATION_MIN and af >= SCENE_CORRELATION_MIN, corr
    assert raw <= UNFOCUSED_CORRELATION_MAX, corr
