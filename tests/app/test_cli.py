"""The ``sarmoco`` command line (:mod:`sarmoco.app.cli`) in process: verbs, messages, exit codes.

Exit status 0 on success, 2 with ``sarmoco: error: KEY: REASON`` on stderr for a bad
configuration (every :class:`~sarmoco.errors.SarmocoError`), 2 with argparse's usage
message for bad arguments.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sarmoco import __version__
from sarmoco.app.cli import main
from sarmoco.daemon.config import describe_keys, load_config
from sarmoco.daemon.links import open_radar


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Exit status, stdout and stderr of ``sarmoco ARGV`` (argparse exits count too)."""
    try:
        status = main(argv)
    except SystemExit as exc:
        status = int(exc.code or 0)
    out, err = capsys.readouterr()
    return status, out, err


def test_config_keys_prints_one_row_per_key(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run_cli(["config", "keys"], capsys)
    lines = out.splitlines()
    assert status == 0
    assert lines[:2] == [
        "| key | type | unit | default | allowed | meaning |",
        "|---|---|---|---|---|---|",
    ]
    keys = [r["key"] for r in describe_keys()]
    assert [line.split("`")[1] for line in lines[2:]] == keys
    assert len(keys) == len(set(keys)) > 40
    row = next(line for line in lines if line.startswith("| `ins.protocol` |"))
    assert row.split(" | ")[1:5] == ["string", "", '`"mavlink"`', '"mavlink", "sbg", "sbg-can"']


def test_config_check_accepts_the_shipped_configuration(
    repo_root: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = repo_root / "systemd" / "sarmoco.toml"
    cfg = load_config(path)
    status, out, err = run_cli(["config", "check", str(path)], capsys)
    assert status == 0 and err == ""
    assert out.startswith(f"{path}: ok (radar {cfg.radar.receive} at ")
    assert f"INS over {cfg.ins.protocol}, recording to {cfg.recorder.directory})" in out


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ('[ins]\nprotocol = "nmea"\n', "ins.protocol: 'nmea' is not one of 'mavlink', 'sbg'"),
        ("[radar]\nprf_hz = -3.0\n", "radar.prf_hz: -3.0 is not > 0"),
        ("[radar]\nprf = 3.0\n", "radar.prf: unknown key (allowed: "),
        ("[ins\n", "not valid TOML"),
    ],
)
def test_config_check_names_the_key_and_the_reason(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], toml: str, message: str
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(toml)
    status, out, err = run_cli(["config", "check", str(path)], capsys)
    assert status == 2 and out == ""
    assert err.startswith(f"sarmoco: error: {path}: " if "TOML" in message else "sarmoco: error: ")
    assert message in err and err.count("\n") == 1


def test_a_missing_file_is_an_error_not_a_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "none.toml"
    status, _, err = run_cli(["run", "--config", str(path)], capsys)
    assert status == 2 and err.startswith(f"sarmoco: error: {path}: cannot read: ")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "the following arguments are required: COMMAND"),
        (["run"], "the following arguments are required: --config"),
        (["config"], "the following arguments are required: ACTION"),
        (["fly"], "invalid choice: 'fly'"),
        (["sim", "--preset", "ku-vehicle"], "one of the arguments --out --serve is required"),
        (["sim", "--preset", "nope", "--out", "x"], "argument --preset: invalid choice: 'nope'"),
    ],
)
def test_bad_arguments_exit_2_with_the_reason(
    capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    status, out, err = run_cli(argv, capsys)
    assert status == 2 and out == "" and message in err
    assert err.startswith("usage: sarmoco")


def test_replay_needs_a_recording_or_both_streams(
    repo_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = str(repo_root / "systemd" / "sarmoco.toml")
    argv = ["replay", "--config", cfg, "--out", str(tmp_path / "r.zarr"), "--radar", "x.vrt"]
    status, _, err = run_cli(argv, capsys)
    assert status == 2
    reason = "give --recording STORE, or both --radar FILE.vrt and --nav FILE"
    assert err == f"sarmoco: error: replay: {reason}\n"
    assert not (tmp_path / "r.zarr").exists()


def test_version_and_the_sim_verbs_help(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run_cli(["--version"], capsys)
    assert (status, out) == (0, f"sarmoco {__version__}\n")
    status, out, _ = run_cli(["sim", "--help"], capsys)
    usage = " ".join(out.split("\n\n")[0].split())  # argparse wraps the line at its width
    assert status == 0 and usage.startswith("usage: sarmoco sim [-h] --preset {thz-spotlight,")
    assert "``sarmoco sim``: simulated hardware" in out  # the module text, added on first use
    assert "With --out, DIR/sarmoco.toml is a daemon configuration" in out


def test_sim_out_writes_a_configuration_the_daemon_accepts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_dir = tmp_path / "sim"
    argv = ["sim", "--preset", "thz-spotlight", "--scale", "0.02", "--out", str(out_dir)]
    status, out, err = run_cli(argv, capsys)
    assert status == 0 and '"event": "written"' in out, err
    cfg = load_config(out_dir / "sarmoco.toml")
    assert cfg.ins.protocol == "mavlink" and cfg.ins.link == str(out_dir / "nav.tlog")
    assert cfg.radar.link == str(out_dir / "radar.vrt") and Path(cfg.radar.link).is_file()
    status, out, _ = run_cli(["config", "check", str(out_dir / "sarmoco.toml")], capsys)
    assert status == 0 and "INS over mavlink" in out
    # a dechirp radar: its context packets give the digitised (beat) band, which the
    # daemon's radar link takes as agreeing with the configuration
    assert cfg.radar.receive == "dechirp"
    rows = np.zeros((16, cfg.radar.n_samples), np.complex64)
    with open_radar(cfg) as src:
        got = src.read_into(rows)
        (context,) = src.decoder.context.values()
    assert got and not any(p.context_mismatch for p in got)
    assert context.bandwidth_hz == pytest.approx(cfg.radar.sample_rate_hz)


def test_the_export_formats_named_in_help_are_the_ones_export_writes(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Each NGA format ``sarmoco --help`` names beside ``export`` has its option in
    ``sarmoco export --help`` (the top-level text claims nothing the verb cannot do)."""
    status, out, _ = run_cli(["--help"], capsys)
    assert status == 0
    (line,) = [x for x in out.splitlines() if x.strip().startswith("export ")]
    named = {f for f in ("SICD", "CPHD", "CRSD", "SIDD") if f in line}
    assert named, line
    status, out, _ = run_cli(["export", "--help"], capsys)
    assert status == 0
    assert {f for f in named if f"--{f.lower()}" not in out} == set(), (line, out)
