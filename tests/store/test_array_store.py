"""The store's ``dem`` group of an array run: written, read back, damage named."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import zarr

from sarmoco.errors import RecorderError
from sarmoco.processing.array.imaging3d import DemProduct
from sarmoco.processing.geometry import ReferenceTrack
from sarmoco.store import schema
from sarmoco.store.reader import open_store
from sarmoco.store.recorder import Recorder


def _dem() -> DemProduct:
    track = ReferenceTrack(
        origin_ned=np.array([1.0, 2.0, -200.0]),
        x_hat=np.array([0.6, 0.8, 0.0]),
        y_hat=np.array([-0.8, 0.6, 0.0]),
        v0_mps=100.0,
        t0_ns=123,
    )
    h = np.arange(12.0).reshape(3, 4)
    h[1, 2] = np.nan
    return DemProduct(h, np.arange(3.0), np.arange(4.0) - 1.5, track, True, (2, 8))


def _store(tmp_path: Path) -> Path:
    path = tmp_path / "run.zarr"
    with Recorder(path, 16, "complex64") as rec:
        rec.add_dem("compensated", *schema.encode_dem(_dem(), 0.9993, 200.0))
    return path


def test_dem_round_trip(tmp_path: Path) -> None:
    store = open_store(_store(tmp_path))
    dem, cell = store.dem("compensated")
    want = _dem()
    np.testing.assert_array_equal(dem.height_m, want.height_m)
    np.testing.assert_array_equal(dem.points_ned(), want.points_ned())
    assert (dem.compensated, dem.blocks, dem.track.t0_ns, cell) == (True, (2, 8), 123, 0.9993)
    assert "dem" not in store.tables()  # a group of products, not a table
    with pytest.raises(RecorderError, match="no DEM product 'dem/uncompensated'"):
        store.dem("uncompensated")


@pytest.mark.parametrize(
    ("attrs", "message"),
    [
        ({"blocks": [2]}, "dem/compensated.blocks: [2] is not two integers"),
        ({"compensated": 1}, "dem/compensated.compensated: 1 is not a bool"),
        ({"reference_track": {"t0_ns": 1}}, "dem/compensated.origin_ned: attribute missing"),
    ],
)
def test_damaged_dem_attributes_are_named(
    tmp_path: Path, attrs: dict[str, object], message: str
) -> None:
    path = _store(tmp_path)
    group = zarr.open_group(str(path / "dem" / "compensated"), mode="r+", zarr_format=3)
    group.update_attributes(attrs)
    with pytest.raises(RecorderError, match=message.replace("[", r"\[").replace("]", r"\]")):
        open_store(path).dem("compensated")
