"""``sarmoco export``: a store's products in the NGA standards, each checked by sarkit.

    sarmoco export STORE [--sicd OUT.nitf] [--cphd OUT.cphd] [--crsd OUT.crsd] [--segment K]

The SICD holds the focused image of one reference-track segment (:mod:`sarmoco.products.sicd`),
the CPHD its recorded echoes as a phase history compensated to the segment's scene centre
by the INS (:func:`sarmoco.products.cphd.from_store`), the CRSD its raw echoes as received,
with the waveform and the antenna track (:mod:`sarmoco.products.crsd`).
Every file written is read back and run through sarkit's consistency checker; a file with
a failure is an error (exit status 2), never a silent product.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

import sarkit.verification as skver

from sarmoco.errors import ConfigError, DataFileError
from sarmoco.store.reader import open_store


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``sarmoco export``."""
    parser.add_argument("store", help="a run or replay store")
    parser.add_argument("--sicd", metavar="OUT.nitf", help="SICD of the focused image")
    parser.add_argument("--cphd", metavar="OUT.cphd", help="CPHD of the recorded echoes")
    parser.add_argument(
        "--crsd", metavar="OUT.crsd", help="CRSD of the raw echoes as received, with the geometry"
    )
    parser.add_argument(
        "--segment", type=int, default=0, help="reference-track segment (0: the first)"
    )


def failures(checker: Callable[[BinaryIO], Any], path: Path, warnings: bool = False) -> list[str]:
    """What sarkit's consistency checker finds wrong in a file ("check: detail" each).

    Parameters
    ----------
    checker : callable
        ``from_file`` of a sarkit consistency class (e.g. ``SicdConsistency.from_file``).
    path : Path
        The file.
    warnings : bool
        Also the failed recommendations (severity ``Warning``), not only the errors.
    """
    with path.open("rb") as f:
        con = checker(f)
        con.check()
    kinds = ("Error", "Warning") if warnings else ("Error",)
    return [
        f"{name}: {d['details']}"
        for name, result in con.failures().items()
        for d in result["details"]
        if not d["passed"] and d["severity"] in kinds
    ]


def checked(checker: Callable[[BinaryIO], Any], path: Path) -> None:
    """Raise a DataFileError naming the file and the checks it fails (errors only)."""
    found = failures(checker, path)
    if found:
        raise DataFileError(f"{path}: fails sarkit's consistency check: " + "; ".join(found))


def run_command(args: argparse.Namespace) -> int:
    """Write the products asked for; 0 when each passed its consistency check."""
    from sarmoco.products.cphd import from_store, write_cphd
    from sarmoco.products.sicd import sicd_product, write_sicd

    if args.sicd is None and args.cphd is None and args.crsd is None:
        raise ConfigError("export: nothing to write (give --sicd, --cphd and/or --crsd)")
    store = open_store(args.store)
    if args.sicd is not None:
        product = sicd_product(store, args.segment)
        out = Path(args.sicd)
        write_sicd(product, out)
        checked(skver.SicdConsistency.from_file, out)
        rows, cols = product.pixels.shape
        print(
            f"{out}: SICD {rows} x {cols} ({product.source}), sarkit SicdConsistency: no failures"
        )
    if args.cphd is not None:
        ph = from_store(store, args.segment)
        out = Path(args.cphd)
        write_cphd(ph, out, f"{store.path.name} segment {args.segment}")
        checked(skver.CphdConsistency.from_file, out)
        vectors, samples = ph.signal.shape
        print(f"{out}: CPHD {vectors} vectors x {samples} samples, CphdConsistency: no failures")
    if args.crsd is not None:
        from sarmoco.products.crsd import write_crsd

        out = Path(args.crsd)
        vectors, samples = write_crsd(store, out, args.segment).signal.shape
        checked(skver.CrsdConsistency.from_file, out)
        print(f"{out}: CRSD {vectors} vectors x {samples} samples, CrsdConsistency: no failures")
    return 0
