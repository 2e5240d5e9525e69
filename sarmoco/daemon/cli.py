"""The ``sarmoco`` command line."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from sarmoco import __version__
from sarmoco.daemon.config import describe_keys, load_config
from sarmoco.errors import SarmocoError


def _cmd_config_check(args: argparse.Namespace) -> int:
    cfg = load_config(args.file)
    print(
        f"{args.file}: ok (radar {cfg.radar.receive} at {cfg.radar.carrier_hz / 1e9:g} GHz, "
        f"INS over {cfg.ins.protocol}, imaging {cfg.imaging.algorithm})"
    )
    return 0


def _cmd_config_keys(args: argparse.Namespace) -> int:
    print("| key | type | unit | default | allowed | meaning |")
    print("|---|---|---|---|---|---|")
    for row in describe_keys():
        print(
            f"| `{row['key']}` | {row['type']} | {row['unit']} | `{row['default']}` | "
            f"{row['allowed']} | {row['doc']} |"
        )
    return 0


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="sarmoco",
        description="Acquisition and focusing daemon for UAV and vehicle-borne SAR.",
    )
    parser.add_argument("--version", action="version", version=f"sarmoco {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    cfg = sub.add_parser("config", help="check a configuration file or list every key")
    cfg_sub = cfg.add_subparsers(dest="config_command", required=True, metavar="ACTION")
    check = cfg_sub.add_parser("check", help="load and validate a TOML configuration")
    check.add_argument("file", help="TOML configuration file")
    check.set_defaults(func=_cmd_config_check)
    keys = cfg_sub.add_parser("keys", help="print every key as a Markdown table")
    keys.set_defaults(func=_cmd_config_keys)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the process exit status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except SarmocoError as exc:
        print(f"sarmoco: error: {exc}", file=sys.stderr)
        return 2
