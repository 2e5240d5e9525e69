"""CPHD out and in on the AFRL GOTCHA phase history (2 x 1 deg, pass 1 HH).

GOTCHA converted to CPHD 1.1.0 passes sarkit's ``CphdConsistency`` with no failures, and
``sarmoco import-cphd`` of that file stores the image that GOTCHA read directly gives
(relative L2 <= 1e-4; measured 1.9e-7). Without the files the tests skip, and under
``CI=true`` they fail (:func:`tests.conftest.shared_files`).
"""

from __future__ import annotations

import dataclasses
import datetime
from pathlib import Path

import numpy as np
import pytest
import sarkit.sicd as sksicd
import sarkit.verification as skver

from sarmoco.app.cli import main
from sarmoco.app.export import failures
from sarmoco.drivers.gotcha import GotchaPass, read_gotcha
from sarmoco.errors import DataFileError
from sarmoco.geodesy import geodetic_to_ecef, ned_to_ecef
from sarmoco.processing.imaging import (
    PlaneGrid,
    backproject,
    compressed_from_phase_history,
    facing_heading,
)
from sarmoco.processing.types import C_MPS
from sarmoco.products.cphd import FxPhaseHistory, from_gotcha, read_cphd, write_cphd
from sarmoco.store.reader import open_store

SIZE, PIXEL_M = 96, 0.2
"""Image of the import: pixels per side and spacing, m (the CLI's --size, --pixel-m)."""


@pytest.fixture(scope="module")
def gotcha(gotcha_files: list[Path]) -> GotchaPass:
    return read_gotcha(gotcha_files)


@pytest.fixture(scope="module")
def cphd_file(gotcha: GotchaPass, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cphd") / "gotcha.cphd"
    write_cphd(from_gotcha(gotcha), path, "gotcha pass1 HH az001-002")
    return path


def test_gotcha_cphd_passes_the_consistency_check(cphd_file: Path) -> None:
    assert failures(skver.CphdConsistency.from_file, cphd_file, warnings=True) == []


def test_the_phase_history_reads_back_as_written(gotcha: GotchaPass, cphd_file: Path) -> None:
    back = read_cphd(cphd_file)
    assert np.array_equal(back.signal, gotcha.phase_history)
    assert np.abs(back.ref_range_m - gotcha.r0_m).max() < 1e-6  # the files' deramp ranges
    assert np.abs(back.scene(back.apc_ecef_m) - gotcha.apc_m).max() < 1e-6
    # CPHD samples are uniform (SC0 + k SCSS); the files' frequencies are float32 values of
    # a uniform grid (840 Hz off it at most, 6e-4 of the 1.47 MHz step)
    step = np.diff(gotcha.freq_hz).mean()
    assert np.abs(back.freq_hz - gotcha.freq_hz).max() < 1e-3 * step
    assert back.polarization == ("H", "H")


def test_imported_cphd_gives_the_image_of_gotcha_read_directly(
    gotcha: GotchaPass, cphd_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = tmp_path / "gotcha.zarr"
    argv = ["import-cphd", str(cphd_file), "--out", str(store)]
    assert main([*argv, "--size", str(SIZE), "--pixel-m", str(PIXEL_M)]) == 0
    imported, _ = open_store(store).image(0)
    grid = PlaneGrid.centred(
        (0.0, 0.0, 0.0), SIZE, SIZE, PIXEL_M, PIXEL_M, facing_heading(gotcha.apc_m, (0, 0, 0))
    )
    rc, r_axis, fc = compressed_from_phase_history(gotcha.phase_history, gotcha.freq_hz)
    direct = backproject(rc, r_axis, gotcha.apc_m, C_MPS / fc, grid, ref_range_m=gotcha.r0_m)
    assert np.array_equal(imported.axis0_m, direct.axis0_m)
    rel = np.linalg.norm(imported.data - direct.data) / np.linalg.norm(direct.data)
    print(f"GOTCHA via CPHD vs direct: relative L2 {rel:.3g}")
    assert rel <= 1e-4


def test_sicd_of_gotcha_through_cphd_passes_the_consistency_check(
    cphd_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``import-cphd --sicd``: the spotlight SICD of the imported image has no failure
    (one recommendation is not met: the 0.2 m grid oversamples the 0.57 m azimuth cell by
    2.8, more than the 2.2 sarkit suggests) and holds the stored pixels."""
    store, sicd = tmp_path / "g.zarr", tmp_path / "g.nitf"
    argv = ["import-cphd", str(cphd_file), "--out", str(store), "--sicd", str(sicd)]
    assert main([*argv, "--size", str(SIZE), "--pixel-m", str(PIXEL_M)]) == 0
    assert failures(skver.SicdConsistency.from_file, sicd) == []
    assert failures(skver.SicdConsistency.from_file, sicd, warnings=True) == [
        "check_iprbw_to_ss_osr_col: Col OSR <= 2.2"
    ]
    image, _ = open_store(store).image(0)
    with sicd.open("rb") as f, sksicd.NitfReader(f) as reader:
        pixels = reader.read_image()
        xml = reader.metadata.xmltree
    assert np.array_equal(pixels, image.data.T[:, ::-1])
    helper = sksicd.XmlHelper(xml)
    assert helper.load("./{*}CollectionInfo/{*}RadarMode/{*}ModeType") == "SPOTLIGHT"
    assert (
        helper.load("./{*}RadarCollection/{*}RcvChannels/{*}ChanParameters/{*}TxRcvPolarization")
        == "H:H"
    )


def test_the_checker_fails_a_cphd_whose_times_run_backwards(
    gotcha: GotchaPass, tmp_path: Path
) -> None:
    ph: FxPhaseHistory = from_gotcha(gotcha)
    bad = tmp_path / "bad.cphd"
    write_cphd(dataclasses.replace(ph, tx_time_s=ph.tx_time_s[::-1].copy()), bad)
    found = failures(skver.CphdConsistency.from_file, bad)
    assert any(f.startswith("check_time_increasing") for f in found), found


def test_import_refuses_a_file_that_is_not_cphd(tmp_path: Path) -> None:
    path = tmp_path / "x.cphd"
    path.write_bytes(b"NITF02.10" + bytes(100))
    with pytest.raises(DataFileError, match="not a readable CPHD"):
        read_cphd(path)


def _small_cphd(path: Path, vectors: int = 8, samples: int = 16) -> Path:
    """A CPHD of ``vectors`` x ``samples`` zeros from a straight pass (no shared files)."""
    t = np.arange(vectors) * 0.01
    apc_ned = np.stack([30.0 * t, np.full(vectors, -300.0), np.full(vectors, -300.0)], axis=1)
    ph = FxPhaseHistory(
        signal=np.zeros((vectors, samples), dtype=np.complex64),
        freq_hz=np.linspace(9.5e9, 10.5e9, samples),
        tx_time_s=t,
        apc_ecef_m=ned_to_ecef(apc_ned, (45.0, 7.0, 0.0)),
        srp_ecef_m=np.tile(geodetic_to_ecef(np.array([45.0, 7.0, 0.0])), (vectors, 1)),
        iarp_lla=(45.0, 7.0, 0.0),
        collection_start=datetime.datetime(2026, 1, 1, tzinfo=datetime.UTC),
    )
    write_cphd(ph, path)
    return path


def test_import_refuses_an_image_or_a_file_that_cannot_fit_before_reading_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``import-cphd`` counts its arrays from the file's header and ``--size`` and refuses
    what does not fit the memory limit (the machine's, or ``--memory-mib``), naming the
    option or the file, before it reads the signal or creates the store."""
    path = _small_cphd(tmp_path / "small.cphd")
    store = tmp_path / "s.zarr"
    status = main(["import-cphd", str(path), "--out", str(store), "--size", "1000000"])
    err = capsys.readouterr().err
    assert status == 2 and err.startswith("sarmoco: error: --size: --size 1000000: the image takes "
                                          f"{10**12 * 32} B ("), err  # fmt: skip
    assert "the machine's memory" in err and not store.exists()
    status = main(["import-cphd", str(path), "--out", str(store), "--size", "8",
                   "--memory-mib", "0.004"])  # fmt: skip
    err = capsys.readouterr().err
    assert status == 2 and err.startswith(
        f"sarmoco: error: {path}: {path} 8 vectors x 16 samples: the range compression takes "
        f"{8 * 16 * 40} B ("
    ), err
    assert f"more than the memory limit {round(0.004 * 2**20)} B (" in err and "--memory-mib" in err
    assert not store.exists()
    status = main(["import-cphd", str(path), "--out", str(store), "--size", "8",
                   "--memory-mib", "1"])  # fmt: skip
    assert status == 0, capsys.readouterr().err
    assert open_store(store).n_images == 1
