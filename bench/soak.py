"""The soak: a long live run with 1 % radar loss and a short INS dropout every minute.

Run as a module (not part of the test suite; it takes the flight's length in wall time)::

    .venv/bin/python -m bench.soak [--minutes 30] [--scale 0.1] [--nice N] [--work DIR]

``sarmoco sim --serve`` flies the ku-vehicle preset (straight track, turbulence, tactical
INS) in real time at the scaled preset's own PRF (every pulse it defines, none thinned)
into ``sarmoco run`` over VITA 49/UDP and MAVLink/UDP on 127.0.0.1, with
``--fault loss=0.01@radar`` and ``--fault ins-dropout=60k:0.2`` for every minute k.
The daemon runs as systemd would start it: ``NOTIFY_SOCKET`` is a real AF_UNIX datagram
socket kept by this script and ``WATCHDOG_USEC`` is the unit's ``WatchdogSec``
(``systemd/sarmoco.service``). ``--nice N`` runs this script (the watchdog listener), the
simulator and the daemon at niceness N (negative: priority over the machine's other work,
as an onboard computer gives its acquisition; needs CAP_SYS_NICE): on a shared machine
whose other load leaves the daemon less CPU than a second of data costs, the soak
otherwise measures the other load.
Measured:

- VmRSS of the daemon every second (``/proc``): medians of the first and last minute
  after a 60 s warm-up, the trend (least squares), the maximum;
- every WATCHDOG=1 arrival: the longest gap against ``WatchdogSec``;
- tiles: every tile index the flown track covers, from the first pulse's footprint to
  the last one's, must be in the store (none missing, none twice);
- pulses: every datagram the simulator did not drop is a committed pulse (the store is
  read back after SIGTERM; late or duplicate arrivals counted by the daemon are
  accounted for), times strictly increasing;
- the load average every minute (the machine is shared).

The result is printed and written to ``DIR/soak.json``; the exit status is 0 only when
every check passed.
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
