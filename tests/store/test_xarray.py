"""``xarray.open_zarr(store, group=...)`` on a run store, with no sarmoco code: every group
opens with named dimensions, and times and image axes come out as coordinates (the
``coordinates`` attributes the recorder writes from :mod:`sarmoco.store.schema`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from sarmoco.store.reader import open_store
from sarmoco.store.recorder import Recorder
from sarmoco.store.schema import AUTOFOCUS
from tests.store import crash_writer as cw

ROWS = 12


def _store(path: Path) -> Path:
    """A complete store with rows in every table and one image tile."""
    ids = np.arange(ROWS, dtype=np.int64)
    with Recorder(path, cw.N_SAMPLES, "int16", chunk_pulses=8, fsync_interval_s=0.0) as rec:
        p = cw.pulse_rows(ids)
        rec.append_pulses(p["t_ns"], p["pulse_id"], p["channel"], p["flags"], p["echo"])
        rec.append_nav(**cw.nav_rows(ids))
        rec.append_motion(**cw.motion_rows(ids))
        rec.append_rows(AUTOFOCUS, cw.autofocus_rows(ids[:3]))
        rec.add_image(cw.image_of(0), 0, 1)
    return path


def _open(path: Path, group: str) -> xr.Dataset:
    return xr.open_zarr(path, group=group, consolidated=False)


def test_every_group_opens_with_dimensions_and_coordinates(tmp_path: Path) -> None:
    path = _store(tmp_path / "run.zarr")
    want = {
        "pulses": ({"pulse": ROWS, "sample": cw.N_SAMPLES, "iq": 2}, {"t_ns"}),
        "nav": ({"nav": ROWS, "ned": 3, "wxyz": 4, "lat_lon_alt": 3}, {"t_ns"}),
        "motion": ({"motion": ROWS, "ned": 3, "wxyz": 4}, {"t_ns"}),
        "autofocus": ({"subaperture": 3, "kappa_order": 3}, {"t_center_s"}),
        "images/tile_000000": ({"axis0": 24, "axis1": 32}, {"axis0_m", "axis1_m"}),
    }
    for group, (sizes, coords) in want.items():
        ds = _open(path, group)
        assert dict(ds.sizes) == sizes, group
        assert set(ds.coords) == coords, group
    pulses = _open(path, "pulses")
    assert pulses["echo"].dims == ("pulse", "sample", "iq")
    assert pulses["echo"].coords["t_ns"].dims == ("pulse",)
    np.testing.assert_array_equal(pulses["t_ns"].values, cw.pulse_rows(np.arange(ROWS))["t_ns"])
    nav = _open(path, "nav")
    assert nav["quat"].dims == ("nav", "wxyz") and "quat" in nav.data_vars
    tile = _open(path, "images/tile_000000")
    assert tile["data"].dims == ("axis0", "axis1")
    np.testing.assert_array_equal(tile["data"]["axis0_m"].values, cw.image_of(0).axis0_m)
    # the coordinates index the image once made the dimensions (one call, no sarmoco)
    near = tile["data"].swap_dims(axis0="axis0_m").sel(axis0_m=1.0, method="nearest")
    np.testing.assert_array_equal(near.values, cw.image_of(0).data[10])


def test_the_store_reader_gives_the_same_coordinates(tmp_path: Path) -> None:
    """``RunStore.dataset`` (cut to the committed rows) agrees with ``open_zarr``."""
    path = _store(tmp_path / "run.zarr")
    store = open_store(path)
    for table in ("pulses", "nav", "motion", "autofocus"):
        mine, theirs = store.dataset(table), _open(path, table)
        assert set(mine.coords) == set(theirs.coords), table
        assert dict(mine.sizes) == dict(theirs.sizes), table
