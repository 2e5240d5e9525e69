"""``sarmoco import-cphd``: focus a CPHD phase history into a store, optionally as SICD.

The image is :func:`sarmoco.products.cphd.focus`'s backprojection on a ground grid of the scene
frame (east, north, up about the CPHD's image-area reference point, IARP).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import lxml.etree
import sarkit.cphd as skcphd
import sarkit.verification as skver

from sarmoco.app.export import checked
from sarmoco.daemon.resources import COMPLEX64_BYTES, Buffer, check_memory, machine_memory_bytes
from sarmoco.drivers.clock import unix_ns_to_gps_ns
from sarmoco.errors import DataFileError
from sarmoco.products.cphd import focus, grid_heading, read_cphd
from sarmoco.products.sicd import spotlight_product, write_sicd
from sarmoco.store.recorder import Recorder

POSITION_BYTES = 3 * 8
"""Bytes of one pixel's ground position (three float64) the backprojection takes."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``sarmoco import-cphd``."""
    parser.add_argument("cphd", help="CPHD file (FX domain, monostatic)")
    parser.add_argument("--out", required=True, help="store to create")
    parser.add_argument("--size", type=int, default=256, help="image pixels per side")
    parser.add_argument("--pixel-m", type=float, default=0.2, help="ground pixel spacing, m")
    parser.add_argument("--sicd", metavar="OUT.nitf", help="also write the image as SICD")
    parser.add_argument(
        "--memory-mib", type=float, help="memory limit, MiB (default: this machine's memory)"
    )


def check_import_memory(path: Path, size: int, memory_mib: float | None) -> None:
    """Refuse an import whose arrays do not fit the memory limit, from the CPHD's header
    (before its signal is read): the phase history (complex64), its range compression
    (the complex128 spectrum, its inverse FFT and the complex64 result) and the
    ``size`` x ``size`` image (complex64 pixels and their float64 ground positions).

    Raises
    ------
    DataFileError
        The file's header is not a readable CPHD.
    ConfigError
        Naming ``--size`` or the file, the bytes and the limit.
    """
    try:
        with path.open("rb") as f, skcphd.Reader(f) as reader:
            channel = reader.metadata.xmltree.find("{*}Data/{*}Channel")
            vectors = int(channel.findtext("{*}NumVectors"))
            samples = int(channel.findtext("{*}NumSamples"))
    except (OSError, ValueError, TypeError, AttributeError, lxml.etree.LxmlError) as exc:
        raise DataFileError(f"{path}: not a readable CPHD ({exc})") from exc
    cells = vectors * samples
    shape = f"{vectors} vectors x {samples} samples"
    buffers = [
        Buffer("phase history", (str(path),), cells * COMPLEX64_BYTES, f"{shape}, complex64"),
        Buffer(
            "range compression", (str(path),), cells * (2 * 16 + COMPLEX64_BYTES),
            f"{shape}, two complex128 and one complex64",
        ),
        Buffer(
            "image", ("--size",), size * size * (COMPLEX64_BYTES + POSITION_BYTES),
            f"{size} x {size} pixels, complex64 and three float64",
        ),
    ]  # fmt: skip
    if memory_mib is None:
        limit, where = machine_memory_bytes(), "the machine's memory; --memory-mib sets another"
    else:
        limit, where = round(memory_mib * 2**20), "--memory-mib"
    check_memory(buffers, limit, where, options={str(path): shape, "--size": size})


def run_command(args: argparse.Namespace) -> int:
    """Read a CPHD, focus it, store the image and optionally write it as SICD
    (``sarmoco import-cphd``); the SICD must pass sarkit's check with no error."""
    path = Path(args.cphd)
    check_import_memory(path, args.size, args.memory_mib)
    ph = read_cphd(path)
    image = focus(ph, args.size, args.pixel_m)
    if args.sicd is not None:
        write_sicd(spotlight_product(ph, image, grid_heading(ph)), Path(args.sicd))
        checked(skver.SicdConsistency.from_file, Path(args.sicd))
    start_ns = unix_ns_to_gps_ns(round(ph.collection_start.timestamp() * 1e9))
    with Recorder(Path(args.out), n_samples=ph.signal.shape[1], raw_echoes=False) as rec:
        rec.set_attribute(
            "imported_from",
            {
                "file": str(path),
                "format": "CPHD 1.1.0 (FX domain)",
                "iarp_lla": list(ph.iarp_lla),
                "frame": "image axes on a ground grid of the IARP's east-north-up frame",
                "vectors": ph.signal.shape[0],
            },
        )
        rec.add_image(
            image,
            start_ns + round(ph.tx_time_s[0] * 1e9),
            start_ns + round(ph.tx_time_s[-1] * 1e9),
        )
    print(f"{args.out}: image {args.size} x {args.size} at {args.pixel_m} m from {path}")
    return 0
