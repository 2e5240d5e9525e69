"""The live page's strip puts its tiles on one dB scale: a tile of noise beside a focused
scene stays dark instead of being stretched to its own peak."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image as PilImage

from sarmoco.daemon.livefeed import LiveFeed
from sarmoco.daemon.status import LiveView
from sarmoco.processing.types import Image
from sarmoco.store.recorder import Recorder

NOISE_BELOW_SCENE_DB = 30.0
"""The noise tile's level under the scene tile's clutter, dB."""


def test_noise_tile_stays_dark_beside_the_scene(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    path = tmp_path / "run.zarr"
    feed = LiveFeed()
    view = LiveView(path, feed, min_interval_s=0.0)
    shape = (60, 40)
    with Recorder(path, 8, "int16", config={}, fsync_interval_s=0.0, live=feed) as rec:
        for k, level in enumerate((1.0, 10 ** (-NOISE_BELOW_SCENE_DB / 20))):
            data = level * (rng.normal(size=shape) + 1j * rng.normal(size=shape))
            if k == 0:
                data[30, 20] = 30.0  # a corner reflector in the scene
            axis0 = 15.0 * k + 0.25 * np.arange(shape[0])
            image = Image(data.astype(np.complex64), axis0, 900 + 0.2 * np.arange(40), "ground")
            rec.add_image(image, k, k + 1)
    png = view.png()
    assert png is not None
    gray = np.asarray(PilImage.open(io.BytesIO(png)).convert("L"), dtype=float)
    half = gray.shape[1] // 2
    scene, noise = gray[:, :half], gray[:, half:]
    # one scale, re the reflector: the clutter ~28 dB below it shows, the noise 30 dB
    # further down is black; each tile on its own peak would show both alike
    print(f"median gray: scene {np.median(scene):.0f}, noise {np.median(noise):.0f}")
    assert np.median(scene) > 255.0 * 0.2 and np.median(noise) < 255.0 * 0.05
    assert scene.max() == 255.0 and noise.max() < 255.0 * 0.5
