"""Fuzzing the store reader on damaged stores.

A small real store (every table, raw echoes, raw INS bytes, an image tile) is written
by the :class:`~sarmoco.store.recorder.Recorder`; each example copies it and damages
its files (``zarr.json`` metadata and chunk files): truncated, bit-flipped, deleted or
overwritten with noise. Everything a user or a replay reads is then read back: the
tables, their xarray datasets, the tiles, the raw INS bytes, the store as navigation and
radar sources (the lazy xarray datasets are built, not computed: a damaged chunk raises
from zarr when a Dataset is computed). Requirements: the reader either reads or raises a
:class:`~sarmoco.errors.RecorderError` naming the store (or the table and column), no
other exception escapes, and no example allocates more than the cap.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sarmoco.errors import RecorderError
from sarmoco.store.reader import StoreNav, StorePulses, open_store
from sarmoco.store.recorder import Recorder
from sarmoco.store.schema import AUTOFOCUS, COMMITTED_ATTR
from tests.fuzz.bounds import assert_named_error, bounded_allocation
from tests.store import crash_writer as cw

FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
N_PULSES = 40


def _write(path: Path) -> Path:
    """A complete small store: 40 pulses in chunks of 16, nav, motion, raw INS bytes,
    autofocus rows and one image tile."""
    ids = np.arange(N_PULSES, dtype=np.int64)
    with Recorder(path, cw.N_SAMPLES, "int16", config={"radar": {"prf_hz": 500.0}},
                  chunk_pulses=16, fsync_interval_s=3600.0, chunk_rows=16) as rec:  # fmt: skip
        rows = cw.pulse_rows(ids)
        rec.append_pulses(rows["t_ns"], rows["pulse_id"], rows["channel"], rows["flags"],
                          rows["echo"])  # fmt: skip
        rec.append_motion(**cw.motion_rows(ids))
        nav = cw.nav_rows(ids)
        nav["kind"] %= 2  # velocity and attitude rows only (the crash writer's 2 is no kind)
        rec.append_nav(nav["t_ns"], nav["kind"], nav["vel_ned"], nav["pos_ned"], nav["quat"],
                       nav["result"], rx_ns=nav["rx_ns"])  # fmt: skip
        for k in range(3):
            rec.append_ins_bytes(cw.raw_chunk(k), rx_ns=k)
        rec.append_rows(AUTOFOCUS, cw.autofocus_rows(np.arange(3, dtype=np.int64)))
        rec.add_image(cw.image_of(0), 0, 1, {"entropy": 0.0})
    return path


_TMP = tempfile.TemporaryDirectory(prefix="sarmoco-fuzz-store-")  # removed at exit
_TEMPLATE = _write(Path(_TMP.name) / "run.zarr")
_FILES = sorted(str(p.relative_to(_TEMPLATE)) for p in _TEMPLATE.rglob("*") if p.is_file())


def read_everything(path: Path) -> None:
    """What ``sarmoco report`` and a replay read from a store."""
    store = open_store(path)
    _ = store.attrs
    for table in store.tables():
        store.read(table)
        store.dataset(table)  # lazy: its chunks are read (and may raise) when computed
    for i in range(store.n_images):
        store.image(i)
    store.ins_bytes()
    if store.committed("ins_raw"):
        store.ins_bytes(0)
    nav = StoreNav(store)
    while not nav.eof:
        nav.poll()
    nav.take_raw()
    pulses = StorePulses(store)
    out = np.empty((16, cw.N_SAMPLES, 2), np.int16)
    while not pulses.eof:
        pulses.read_into(out)


def test_the_undamaged_store_reads() -> None:
    read_everything(_TEMPLATE)
    assert open_store(_TEMPLATE).committed("pulses") == N_PULSES


@st.composite
def damage(draw: Any) -> list[tuple[str, str, int, int]]:
    """Edits of the store's files: (file, operation, position fraction, bit)."""
    return draw(st.lists(st.tuples(
        st.sampled_from(_FILES), st.sampled_from(["truncate", "flip", "delete", "noise"]),
        st.integers(0, 1000), st.integers(0, 7),
    ), min_size=1, max_size=3))  # fmt: skip


def _apply(root: Path, edits: list[tuple[str, str, int, int]]) -> None:
    for name, op, where, bit in edits:
        f = root / name
        if not f.exists():
            continue
        data = bytearray(f.read_bytes())
        pos = where * len(data) // 1001
        if op == "delete":
            f.unlink()
            continue
        if op == "truncate":
            del data[pos:]
        elif op == "flip" and data:
            data[pos] ^= 1 << bit
        else:
            data[pos : pos + 16] = np.random.default_rng(where).bytes(16)
        f.write_bytes(bytes(data))


@FUZZ
@given(damage())
def test_damaged_store_reads_or_names_the_damage(edits: list[tuple[str, str, int, int]]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "run.zarr"
        shutil.copytree(_TEMPLATE, root)
        _apply(root, edits)
        try:
            with bounded_allocation(16 << 20):
                read_everything(root)
        except RecorderError as exc:
            assert_named_error(exc, str(root))


@pytest.mark.parametrize("value", ["40", -1, True, 1e300, 10**30, None, [40], {"rows": 40}, 41])
def test_committed_attribute_of_the_wrong_type_or_range(value: Any, tmp_path: Path) -> None:
    """Zarr attributes are untrusted JSON: a ``committed`` that is not an int between 0 and
    the arrays' length is refused with a RecorderError naming the table and attribute."""
    root = tmp_path / "run.zarr"
    shutil.copytree(_TEMPLATE, root)
    meta_path = root / "pulses" / "zarr.json"
    meta = json.loads(meta_path.read_text())
    meta["attributes"][COMMITTED_ATTR] = value
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(RecorderError) as err:
        read_everything(root)
    assert_named_error(err.value, f"pulses.{COMMITTED_ATTR}")


@pytest.mark.parametrize(
    ("name", "op"),
    [
        ("nav/t_ns/c/0", "truncate"),  # numcodecs RuntimeError: Zstd decompression error
        ("pulses/echo/c/0/0/0", "truncate"),  # ValueError: cannot reshape array of size 0
        ("autofocus/a_y_mps2/zarr.json", "truncate"),  # JSONDecodeError
        ("images/zarr.json", "delete"),  # zarr GroupNotFoundError
        ("ins_raw/offset/zarr.json", "delete"),  # KeyError 'offset' in ins_bytes()
    ],
)
def test_found_by_fuzzing(name: str, op: str, tmp_path: Path) -> None:
    """Regressions: each of these escaped the reader as a zarr, numcodecs, json or
    builtin exception; now a RecorderError naming the store."""
    root = tmp_path / "run.zarr"
    shutil.copytree(_TEMPLATE, root)
    _apply(root, [(name, op, 0, 0)])
    with pytest.raises(RecorderError) as err:
        read_everything(root)
    assert_named_error(err.value, str(root))
