"""How long a strip's store takes to open and to close, from ``sarmoco run``'s JSON log.

Run as a script: ``python bench/strip_times.py LOG [LOG ...]``. For each ``strip opened``
and ``strip closed`` record of a daemon run with ``camera.store_per_capture``, prints the
time since the capture command that asked for it (the component's ``camera capture``
record), ms, and the pulses a closed strip holds.
"""

from __future__ import annotations

import argparse
import datetime
import json
from pathlib import Path
from typing import Any


def strip_times(log: Path) -> list[tuple[str, float, int | None]]:
    """``(record, ms since its capture command, pulses of a closed strip)`` of each strip
    opened or closed in ``log``."""
    records: list[dict[str, Any]] = [
        json.loads(line) for line in log.read_text().splitlines() if line.startswith("{")
    ]
    out: list[tuple[str, float, int | None]] = []
    asked: datetime.datetime | None = None
    for r in records:
        at = datetime.datetime.fromisoformat(r["ts"])
        if r["msg"] == "camera capture":
            asked = at
        elif r["msg"] in ("strip opened", "strip closed") and asked is not None:
            ms = (at - asked).total_seconds() * 1e3
            out.append((r["msg"], ms, r.get("pulses_received")))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("logs", nargs="+", type=Path, help="daemon JSON logs (stderr)")
    for log in parser.parse_args().logs:
        for what, ms, pulses in strip_times(log):
            held = "" if pulses is None else f", {pulses} pulses"
            print(f"{log}: {what} {ms:.0f} ms after the command{held}")


if __name__ == "__main__":
    main()
