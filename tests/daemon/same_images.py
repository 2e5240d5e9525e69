"""What "the same image" means when a replay is compared with the run it replays."""

from __future__ import annotations

import numpy as np

from sarmoco.store.reader import RunStore

REPLAY_REL_L2 = 1e-5
"""Largest relative L2 difference of a replayed tile from the recorded one (a replay of a
replay is compared bit for bit instead: ``test_runner``)."""


def assert_same_images(a: RunStore, b: RunStore, rel_l2: float = REPLAY_REL_L2) -> None:
    """Both stores hold the same tiles: equal along-track axes, data within ``rel_l2``."""
    assert a.n_images == b.n_images > 0
    for k in range(a.n_images):
        ia, ib = a.image(k)[0], b.image(k)[0]
        np.testing.assert_array_equal(ia.axis0_m, ib.axis0_m)
        err = np.linalg.norm(ia.data - ib.data) / np.linalg.norm(ia.data)
        assert err < rel_l2, (k, err)
