"""Every documented option value, end to end on the independent harness's scenario.

Run as ``.venv/bin/python -m bench.bench_option_values [--workdir DIR] [--booleans]
[--only KEY ...]`` from the project root (about 35 s of CPU per value).

The keys with a fixed set of values (``sarmoco config keys``: the Literal and choices keys;
with ``--booleans`` the true/false keys too) are each run once per value other than their
default on the reference scenario of ``../shared/acceptance/run_blackbox.py`` (stripmap,
15 GHz, 7 point targets, a real ArduPilot flight's motion, a tactical-to-MEMS INS error):
the harness writes the scenario and its configuration once, each value is the harness's
configuration with that one key changed, replayed by ``sarmoco replay`` and scored by the
harness's ``score.py``. Values that describe the data rather than choose a method
(sample type, INS protocol, look side) are run on the harness's scenario of that kind;
those the harness cannot make (a dechirp receiver, a down-chirp, conjugated I/Q, an
array, SBG over CAN) are listed as not run, with the reason. Prints one line per value:
the harness's verdict (PASS: every target at PSLR <= -12.5 dB and IRW <= 1.1 x the
unweighted theory, so a window, which widens the main lobe by design, shows as an IRW
failure with its PSLR), the worst PSLR and the worst IRW ratio.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
import typing
from pathlib import Path

import tomli_w

from sarmoco.daemon.config import Config, describe_keys

REPO = Path(__file__).resolve().parents[1]
ACCEPTANCE = REPO.parent / "shared" / "acceptance"
HARNESS = ACCEPTANCE / "run_blackbox.py"
SCORE = ACCEPTANCE / "score.py"

SCENARIO_OPTIONS: dict[tuple[str, object], list[str]] = {
    ("radar.sample_format", "float32"): ["--format", "float32"],
    ("ins.protocol", "sbg"): ["--nav-format", "sbg"],
    ("geometry.look_side", "left"): ["--look-side", "left"],
}
"""Values that describe the data: the harness's scenario of that kind (its own config)."""

NOT_RUN: dict[tuple[str, object], str] = {
    ("radar.receive", "dechirp"): "the harness's radar is pulsed LFM (matched filter)",
    ("radar.chirp_direction", "down"): "the harness's chirp sweeps up",
    ("radar.mode", "array"): "the harness flies one side-looking channel",
    ("ins.protocol", "sbg-can"): "the harness writes no CAN log",
    ("radar.iq_conjugate", True): "the harness's I/Q is not conjugated",
    ("array.roll_compensation", False): "array mode only",
    ("array.record_uncompensated", False): "array mode only",
}
"""Values the harness's scenario cannot exercise, with the reason."""

VERDICT = re.compile(
    r"VERDICT: (\w+) -- (\d+)/(\d+) targets measured; worst PSLR (\S+) dB \(([^)]*)\), "
    r"worst IRW ratio (\S+) \(([^)]*)\)"
)


def option_values(booleans: bool) -> list[tuple[str, object]]:
    """Every (key, value) with a fixed set of values, other than the key's default."""
    hints = typing.get_type_hints(Config)
    out: list[tuple[str, object]] = []
    for row in describe_keys():
        section, name = row["key"].split(".")
        tp = typing.get_type_hints(hints[section])[name]
        default = getattr(getattr(Config(), section), name)
        if typing.get_origin(tp) is typing.Literal:
            values: tuple[object, ...] = typing.get_args(tp)
        elif tp is bool and booleans:
            values = (True, False)
        else:
            values = _choices(hints[section], name)
        out += [(row["key"], v) for v in values if v != default or type(v) is not type(default)]
    return out


def _choices(section: type, name: str) -> tuple[object, ...]:
    """The ``choices`` of a string key whose values come from a registry (else none)."""
    meta = next(f for f in dataclasses.fields(section) if f.name == name).metadata
    return tuple(meta.get("choices", ()))


def harness(workdir: Path, options: list[str]) -> str:
    """Run the harness on a scenario; return its output."""
    done = subprocess.run(
        [sys.executable, str(HARNESS), "--workdir", str(workdir), "--repo", str(REPO),
         "--sarmoco", f"{shlex.quote(sys.executable)} -m sarmoco", *options],
        capture_output=True, text=True, cwd=REPO,
    )  # fmt: skip
    return done.stdout + done.stderr


def replay_with(base: Path, key: str, value: object, out_dir: Path) -> str:
    """Replay the harness's files of ``base`` with ``key = value``; return the score's output."""
    table = tomllib.loads((base / "sarmoco.toml").read_text())
    section, name = key.split(".")
    table.setdefault(section, {})[name] = value
    out_dir.mkdir(parents=True)
    cfg = out_dir / "sarmoco.toml"
    cfg.write_text(tomli_w.dumps(table))
    nav = table["ins"]["link"]
    run = [sys.executable, "-m", "sarmoco", "replay", "--config", str(cfg),
           "--radar", str(base / "radar.vrt"), "--nav", str(base / nav),
           "--out", str(out_dir / "OUT.zarr")]  # fmt: skip
    r = subprocess.run(run, capture_output=True, text=True, cwd=base)
    (out_dir / "replay.log").write_text(r.stdout + "\n--- stderr ---\n" + r.stderr)
    if r.returncode != 0 or not (out_dir / "OUT.zarr").exists():
        tail = (r.stdout + r.stderr).strip().splitlines()[-1:] or [""]
        return f"replay failed (exit {r.returncode}): {tail[0]}"
    s = subprocess.run(
        [sys.executable, str(SCORE), str(out_dir / "OUT.zarr"), str(base / "truth.json")],
        capture_output=True, text=True, cwd=base,
    )  # fmt: skip
    return s.stdout + s.stderr


def summary(text: str) -> str:
    """One line from the harness's or score's output."""
    m = VERDICT.search(text)
    if m is None:
        lines = [ln for ln in text.splitlines() if "VERDICT" in ln or "fail" in ln.lower()]
        return (lines[-1] if lines else text.strip().splitlines()[-1])[:110]
    verdict, found, total, pslr, pslr_at, irw, irw_at = m.groups()
    return (
        f"{verdict:4s} {found}/{total} found, worst PSLR {float(pslr):7.2f} dB ({pslr_at}), "
        f"IRW {float(irw):.3f} x ({irw_at})"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workdir", type=Path, help="keep every run here (default: a temp dir)")
    ap.add_argument("--booleans", action="store_true", help="also each true/false key")
    ap.add_argument("--only", nargs="*", default=[], help="only these keys (e.g. imaging.window)")
    a = ap.parse_args(argv)
    work = a.workdir or Path(tempfile.mkdtemp(prefix="sarmoco_options_"))
    work.mkdir(parents=True, exist_ok=True)
    values = [(k, v) for k, v in option_values(a.booleans) if not a.only or k in a.only]
    t0 = time.perf_counter()
    base = work / "reference"
    if not (base / "truth.json").exists():
        shutil.rmtree(base, ignore_errors=True)
        print(f"{'reference (every default)':34s} {summary(harness(base, []))}", flush=True)
    for i, (key, value) in enumerate(values):
        label = f"{key} = {tomli_w.dumps({'v': value})[4:].strip()}"
        if (key, value) in NOT_RUN:
            print(f"{label:34s} not run: {NOT_RUN[key, value]}", flush=True)
            continue
        where = work / f"{i:02d}-{key}-{value}".replace(" ", "")
        shutil.rmtree(where, ignore_errors=True)
        if (key, value) in SCENARIO_OPTIONS:
            text = harness(where, SCENARIO_OPTIONS[key, value])
        else:
            text = replay_with(base, key, value, where)
        print(f"{label:34s} {summary(text)}", flush=True)
    print(f"{len(values)} values in {time.perf_counter() - t0:.0f} s; runs kept in {work}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
