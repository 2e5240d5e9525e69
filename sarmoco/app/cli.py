"""The ``sarmoco`` command line.

Each verb imports what it needs when it runs: ``sarmoco run`` (the daemon process)
never loads the simulator, whose modules are imported by ``sim`` and ``demo`` only.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from sarmoco import __version__
from sarmoco.daemon.config import Config, keys_markdown, load_config
from sarmoco.errors import ConfigError, SarmocoError


class VerbParser(argparse.ArgumentParser):
    """A subcommand parser that can add its arguments on first use.

    ``add_arguments`` runs just before the verb's command line is parsed (or its
    ``--help`` printed), so the imports it needs happen only for that verb.

    Parameters
    ----------
    add_arguments : callable, optional
        Adds the verb's arguments to this parser.
    **kwargs
        Passed to :class:`argparse.ArgumentParser`.
    """

    def __init__(
        self,
        *,
        add_arguments: Callable[[argparse.ArgumentParser], None] | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        self._add_arguments = add_arguments

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """Add the deferred arguments (once), then parse as usual."""
        if self._add_arguments is not None:
            add, self._add_arguments = self._add_arguments, None
            add(self)
        return super().parse_known_args(args, namespace)


def _load_checked(path: str) -> Config:
    """The configuration at ``path``, refused when its buffers do not fit the machine
    (:func:`~sarmoco.daemon.resources.check_resources`)."""
    from sarmoco.daemon.resources import check_resources

    cfg = load_config(path)
    check_resources(cfg)
    return cfg


def _cmd_config_check(args: argparse.Namespace) -> int:
    from sarmoco.daemon.resources import data_rate_bytes_s, human_bytes, memory_limit, plan

    cfg = _load_checked(args.file)
    buffers = plan(cfg)
    limit, where = memory_limit(cfg)
    rate = data_rate_bytes_s(cfg)
    print(
        f"{args.file}: ok (radar {cfg.radar.receive} at {cfg.radar.carrier_hz / 1e9:g} GHz, "
        f"INS over {cfg.ins.protocol}, recording to {cfg.recorder.directory})"
    )
    print(
        f"echo data rate {rate * 8e-6:.4g} Mbit/s ({human_bytes(rate)}/s); buffers "
        f"{human_bytes(sum(b.nbytes for b in buffers))} of {human_bytes(limit)} ({where}):"
    )
    for b in buffers:
        print(f"  {b.name}: {human_bytes(b.nbytes)} ({b.how}; {', '.join(b.keys)})")
    return 0


def _cmd_config_keys(args: argparse.Namespace) -> int:
    print(keys_markdown(), end="")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from sarmoco.daemon.logging_setup import install_sighup, setup_logging
    from sarmoco.daemon.runner import run_live

    cfg = _load_checked(args.config)
    setup_logging(cfg.status.log_level, "json")
    install_sighup()
    store = Path(args.store) if args.store else None
    return run_live(cfg, store, args.exit_when_idle)


def _cmd_replay(args: argparse.Namespace) -> int:
    from sarmoco.daemon.runner import replay_files, replay_store

    cfg = _load_checked(args.config)
    out = Path(args.out)
    if not args.recording and not (args.radar and args.nav):
        raise ConfigError("replay: give --recording STORE, or both --radar FILE.vrt and --nav FILE")
    if cfg.radar.mode == "array":
        return _replay_array(args, cfg, out)
    if args.recording:
        summary = replay_store(cfg, Path(args.recording), out, progress=not args.quiet)
    else:
        summary = replay_files(cfg, Path(args.radar), Path(args.nav), out, not args.quiet)
    print(f"{out}: {summary.pulses_processed} pulses focused, {summary.tiles} tiles")
    from sarmoco.products.northup import write_north_up_images

    for line in write_north_up_images(out).lines():
        print(f"{out}: {line}")
    return 0


def _replay_array(args: argparse.Namespace, cfg: Config, out: Path) -> int:
    from sarmoco.daemon.array_pipeline import replay_array_files, replay_array_store

    if args.recording:
        s = replay_array_store(cfg, Path(args.recording), out)
    else:
        s = replay_array_files(cfg, Path(args.radar), Path(args.nav), out)
    print(f"{out}: {s.pulses_imaged} of {s.pulses} array pulses imaged; {s.dem_text()}")
    return 0


def _add_batch_arguments(parser: argparse.ArgumentParser) -> None:
    from sarmoco.app.batch import add_arguments

    add_arguments(parser)


def _cmd_batch(args: argparse.Namespace) -> int:
    from sarmoco.app.batch import run_command

    return run_command(args)


def _add_export_arguments(parser: argparse.ArgumentParser) -> None:
    from sarmoco.app.export import add_arguments

    add_arguments(parser)


def _cmd_export(args: argparse.Namespace) -> int:
    from sarmoco.app.export import run_command

    return run_command(args)


def _add_import_cphd_arguments(parser: argparse.ArgumentParser) -> None:
    from sarmoco.app.import_cphd import add_arguments

    add_arguments(parser)


def _cmd_import_cphd(args: argparse.Namespace) -> int:
    from sarmoco.app.import_cphd import run_command

    return run_command(args)


def _cmd_report(args: argparse.Namespace) -> int:
    from sarmoco.app.truth import read_true_terrain
    from sarmoco.products.array_report import is_array_store, summary_text, write_array_report
    from sarmoco.products.report import write_report
    from sarmoco.store.reader import open_store

    store = Path(args.store)
    out = Path(args.out) if args.out else store.with_suffix(".report")
    if is_array_store(open_store(store)):
        truth = None if args.truth is None else read_true_terrain(Path(args.truth))
        dems = write_array_report(open_store(store), out, truth)
        print(json.dumps(dems.as_dict()) if args.json else summary_text(dems).rstrip("\n"))
        return 0
    if args.truth is not None:
        raise ConfigError("report --truth: only an array run's DEM is compared with a truth")
    summary = write_report(store, out)
    if args.json:
        print(json.dumps(summary.as_dict(), default=float))
        return 0
    print((out / "report.txt").read_text(), end="")
    print(f"quicklooks and report.json in {out}")
    return 0


def _cmd_verify(args: argparse.Namespace) -> int:
    from sarmoco.store.verify import verify_store

    report = verify_store(args.store)
    for fault in report.faults:
        print(f"{args.store}/{fault}")
    if report.unchecked:
        print(f"{len(report.unchecked)} arrays carry no checksum (read, not checked): "
              + ", ".join(report.unchecked))  # fmt: skip
    verdict = f"{len(report.faults)} damaged" if report.faults else "intact"
    print(f"{args.store}: {report.chunks} chunks of {report.arrays} arrays read: {verdict}")
    return 1 if report.faults else 0


def _add_sim_arguments(parser: argparse.ArgumentParser) -> None:
    from sarmoco.app.simcommand import add_arguments

    add_arguments(parser)


def _cmd_sim(args: argparse.Namespace) -> int:
    from sarmoco.app.simcommand import run_command, scenario_overrides

    status = run_command(args)
    if status == 0 and args.out is not None and args.preset != "mimo-array":  # writes its own
        from sarmoco.app.simconfig import config_table, write_config
        from sarmoco.sim.outfiles import NAV_FILES, RADAR_FILE
        from sarmoco.sim.scenario import load_preset

        out = Path(args.out)
        table = config_table(
            load_preset(args.preset, args.scale, **scenario_overrides(args)),
            radar={"link": str(out / RADAR_FILE), "sample_format": args.payload},
            ins={"protocol": "mavlink", "link": str(out / NAV_FILES["mavlink"])},
            recorder={"directory": str(out)},
        )
        write_config(out / "sarmoco.toml", table)
    return status


def _add_demo_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    parser.add_argument("--scale", type=float, default=0.1, help="ku-vehicle scenario scale")
    parser.add_argument(
        "--scene", default="extended", choices=("points", "extended"),
        help="extended (default): terrain clutter and corner reflectors; points: 3 targets",
    )  # fmt: skip
    parser.add_argument(
        "--status-port", type=int, metavar="PORT",
        help="serve the daemon's /status and live page on 127.0.0.1:PORT (default: a free port)",
    )  # fmt: skip


def _add_bench_arguments(parser: argparse.ArgumentParser) -> None:
    from sarmoco.app.benchcmd import add_arguments

    add_arguments(parser)


def _cmd_bench(args: argparse.Namespace) -> int:
    from sarmoco.app.benchcmd import run_command

    return run_command(args)


def _cmd_demo(args: argparse.Namespace) -> int:
    from sarmoco.app.demo import run_loopback

    out = Path(args.out)
    if (out / "truth.json").exists():  # an earlier demo's output: replace it
        shutil.rmtree(out)
    if args.status_port is None:
        run_loopback(out, args.scale, scene=args.scene)
    else:
        print(f"live page: http://127.0.0.1:{args.status_port}/ while the daemon runs",
              file=sys.stderr)  # fmt: skip
        run_loopback(out, args.scale, scene=args.scene, status={"http_port": args.status_port})
    print((out / "report" / "report.txt").read_text(), end="")
    print(f"store {out / 'run.zarr'}, quicklooks in {out / 'report'}")
    return 0


def _add_config_verb(sub: Any) -> None:
    """``sarmoco config check`` and ``sarmoco config keys``."""
    cfg = sub.add_parser("config", help="check a configuration file or list every key")
    cfg_sub = cfg.add_subparsers(dest="config_command", required=True, metavar="ACTION")
    check = cfg_sub.add_parser("check", help="load and validate a TOML configuration")
    check.add_argument("file", help="TOML configuration file")
    check.set_defaults(func=_cmd_config_check)
    keys = cfg_sub.add_parser("keys", help="print every key as a Markdown table")
    keys.set_defaults(func=_cmd_config_keys)


def _add_store_verbs(sub: Any) -> None:
    """``sarmoco report`` and ``sarmoco verify``: what is read from a store."""
    report = sub.add_parser("report", help="quicklook PNGs and metrics of a store")
    report.add_argument("store", help="a run or replay store")
    report.add_argument("--out", help="output folder (default: STORE with suffix .report)")
    report.add_argument("--truth", help="array run: truth.json of the simulated run (DEM stats)")
    report.add_argument("--json", action="store_true", help="print the summary as one JSON")
    report.set_defaults(func=_cmd_report)

    verify = sub.add_parser(
        "verify",
        help="read every chunk of a store and check its checksum; exit 1 when any is damaged",
    )
    verify.add_argument("store", help="a run or replay store")
    verify.set_defaults(func=_cmd_verify)


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="sarmoco",
        description="Acquisition and focusing daemon for UAV and vehicle-borne SAR.",
    )
    parser.add_argument("--version", action="version", version=f"sarmoco {__version__}")
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=VerbParser
    )

    _add_config_verb(sub)
    run = sub.add_parser("run", help="the live daemon: read INS and radar, focus, record")
    run.add_argument("--config", required=True, help="TOML configuration file")
    run.add_argument("--store", help="store to create (default: a new one in recorder.directory)")
    run.add_argument(
        "--exit-when-idle", type=float, metavar="S",
        help="stop cleanly after S seconds without radar pulses (simulation, tests)",
    )  # fmt: skip
    run.set_defaults(func=_cmd_run)

    replay = sub.add_parser("replay", help="ground replay of logged streams on a virtual clock")
    replay.add_argument("--config", required=True, help="TOML configuration file")
    replay.add_argument("--recording", help="a store written by `sarmoco run`")
    replay.add_argument("--radar", help="VITA 49.2 packet file (.vrt)")
    replay.add_argument("--nav", help="INS log (.tlog, .bin, SBG binary, CAN log)")
    replay.add_argument("--out", required=True, help="store to create")
    replay.add_argument("--quiet", action="store_true", help="no progress bar")
    replay.set_defaults(func=_cmd_replay)

    batch = sub.add_parser(
        "batch",
        help="reprocess recordings in blocks on a dask.distributed cluster (ground)",
        add_arguments=_add_batch_arguments,
    )
    batch.set_defaults(func=_cmd_batch)

    export = sub.add_parser(
        "export",
        help="a store's image as SICD and its phase history as CPHD (sarkit-checked)",
        add_arguments=_add_export_arguments,
    )
    export.set_defaults(func=_cmd_export)

    import_cphd = sub.add_parser(
        "import-cphd",
        help="focus a CPHD phase history (FX domain) into a store",
        add_arguments=_add_import_cphd_arguments,
    )
    import_cphd.set_defaults(func=_cmd_import_cphd)

    _add_store_verbs(sub)

    sim = sub.add_parser(
        "sim",
        help="simulated radar and INS: write files (--out) or serve live links (--serve)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="With --out, DIR/sarmoco.toml is a daemon configuration for the scenario "
        "(radar.vrt + nav.tlog; change ins.protocol/link for ins.sbg or the CAN log ins.log).",
        add_arguments=_add_sim_arguments,
    )
    sim.set_defaults(func=_cmd_sim)

    bench = sub.add_parser(
        "bench",
        help="can this computer keep up? simulated radar and INS on loopback into the daemon",
        add_arguments=_add_bench_arguments,
    )
    bench.set_defaults(func=_cmd_bench)

    demo = sub.add_parser(
        "demo",
        help="simulated hardware + daemon on loopback, then the report (the main job)",
        add_arguments=_add_demo_arguments,
    )
    demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the process exit status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except SarmocoError as exc:
        print(f"sarmoco: error: {exc}", file=sys.stderr)
        return 2
