"""The soak: a long live run with 1 % radar loss and a short INS dropout every minute.

The command line of :mod:`tests.workloads.soak` (the workload, shared with the tests)::

    .venv/bin/python -m bench.soak [--minutes 30] [--scale 0.1] [--nice N] [--work DIR]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from tests.workloads.soak import soak


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=30.0, help="flight length, minutes")
    ap.add_argument("--scale", type=float, default=0.1, help="ku-vehicle scale")
    ap.add_argument("--loss", type=float, default=0.01, help="radar datagram loss probability")
    ap.add_argument("--dropout-s", type=float, default=0.2, help="INS dropout each minute, s")
    ap.add_argument("--nice", type=int, default=0, help="niceness of simulator and daemon")
    ap.add_argument("--work", type=Path, default=None, help="folder (default: a new temp one)")
    args = ap.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="sarmoco-soak-"))
    work.mkdir(parents=True, exist_ok=True)
    record = soak(work, args.minutes, args.scale, args.loss, args.dropout_s, args.nice)
    (work / "soak.json").write_text(json.dumps(record, indent=1))
    shown = {k: v for k, v in record.items() if k != "status"}
    print(json.dumps(shown, indent=1))
    print(f"soak {'PASSED' if all(record['checks'].values()) else 'FAILED'}; record in {work}")
    return 0 if all(record["checks"].values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
