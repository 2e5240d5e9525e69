"""The independent acceptance harness over a range of seeds: the worst target of each.

Run as ``.venv/bin/python -m bench.bench_blackbox_seeds 1-20 [harness options]``, e.g.
``... 1-20``, ``... 3 --nav-messages global``, ``... 1-5 --look-side left --heading 200``.

Every seed runs ``../shared/acceptance/run_blackbox.py`` (scenario, ``sarmoco replay`` of
this checkout's ``.venv``, scoring) in its own folder under a temporary directory. The
harness's per-target scores (its ``score.json``) give one row per seed: the worst target
and axis by PSLR, the worst IRW over theory, the largest relative position error after
the common offset (``pos rel``, m) and the harness's verdict (PSLR <= -12.5 dB and IRW
<= 1.1 x theory on every target, both axes). Then, per target, on how many seeds it
passed and its worst PSLR. About half a minute a seed on two cores.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
HARNESS = REPO.parent / "shared" / "acceptance" / "run_blackbox.py"
"""The independent end-to-end check beside the repository (read-only for the project)."""

PSLR_DB = -12.5
IRW_RATIO = 1.1
"""The harness's default thresholds (a target passes at or under both, both axes)."""


def seed_range(text: str) -> list[int]:
    """``"1-20"`` or ``"3"`` or ``"1,4,7"`` as a list of seeds."""
    seeds: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        seeds.extend(range(int(lo), int(hi or lo) + 1))
    return seeds


def run_seed(seed: int, options: list[str], work: Path) -> tuple[int, list[dict[str, Any]]]:
    """Run the harness on one seed; its exit status and per-target rows (``score.json``)."""
    folder = work / f"seed{seed}"
    cmd = [sys.executable, str(HARNESS), "--workdir", str(folder), "--seed", str(seed)]
    done = subprocess.run(
        [*cmd, "--repo", str(REPO), *options], capture_output=True, text=True, check=False
    )
    score = folder / "score.json"
    if not score.is_file():
        tail = (done.stdout + done.stderr).strip().splitlines()[-3:]
        print(f"seed {seed}: no score (exit {done.returncode}): {' | '.join(tail)}")
        return done.returncode, []
    rows: list[dict[str, Any]] = json.loads(score.read_text())["rows"]
    return done.returncode, rows


def target_passes(row: dict[str, Any]) -> bool:
    """Whether a target was found and meets the PSLR and IRW thresholds in both axes."""
    return bool(row.get("found")) and all(
        row[ax]["pslr_db"] <= PSLR_DB and row[ax]["irw_ratio"] <= IRW_RATIO for ax in ("az", "rg")
    )


def seed_line(seed: int, code: int, rows: list[dict[str, Any]]) -> str:
    """One table row: worst PSLR (target, axis), worst IRW ratio, largest pos rel, verdict."""
    found = [r for r in rows if r.get("found")]
    if not found:
        return f"{seed:>4} | {'no target measured':<44} | FAIL (exit {code})"
    pslr, tgt, ax = max((r[a]["pslr_db"], r["id"], a) for r in found for a in ("az", "rg"))
    irw = max(r[a]["irw_ratio"] for r in found for a in ("az", "rg"))
    rel = max(r["rel_err"] for r in found if r.get("rel_err") is not None)
    verdict = "PASS" if code == 0 else f"FAIL ({len(rows) - len(found)} not found)"
    if code != 0 and len(found) == len(rows):
        verdict = "FAIL"
    return f"{seed:>4} | {pslr:8.2f} T{tgt} {ax} | {irw:9.3f} | {rel:7.3f} | {verdict}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("seeds", type=seed_range, help='seeds: "1-20", "3" or "1,4,7"')
    ap.add_argument("--keep", help="keep every seed's folder under this directory")
    args, options = ap.parse_known_args(argv)
    if not HARNESS.is_file():
        print(f"the acceptance harness is not at {HARNESS}")
        return 2
    print(f"harness options: {' '.join(options) or '(defaults)'}")
    print("seed | worst PSLR [dB]   | worst IRW | pos rel | verdict")
    print("-----+-------------------+-----------+---------+--------")
    per_target: dict[int, list[tuple[bool, float]]] = {}
    failed = 0
    with tempfile.TemporaryDirectory(prefix="blackbox_seeds_") as tmp:
        work = Path(args.keep) if args.keep else Path(tmp)
        for seed in args.seeds:
            code, rows = run_seed(seed, options, work)
            failed += code != 0
            print(seed_line(seed, code, rows), flush=True)
            for r in rows:
                worst = max(r[a]["pslr_db"] for a in ("az", "rg")) if r.get("found") else 0.0
                per_target.setdefault(r["id"], []).append((target_passes(r), worst))
    n = len(args.seeds)
    print(f"\n{n - failed}/{n} seeds pass")
    print("target | seeds passed | worst PSLR [dB] | seeds <= -13.0 dB")
    for tgt, results in sorted(per_target.items()):
        passed = sum(ok for ok, _ in results)
        worst = max(p for _, p in results)
        sharp = sum(p <= -13.0 for _, p in results)
        k = len(results)
        print(f"  T{tgt:<4} | {passed:>5}/{k:<6} | {worst:15.2f} | {sharp:>3}/{k}")
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
