"""The ``pymc-vcc`` command line."""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from collections.abc import Sequence
from pathlib import Path


def _bench(args: argparse.Namespace) -> int:
    from pymc_vcc.benchmarks import BENCHMARKS

    selected = args.only or list(BENCHMARKS)
    unknown = sorted(set(selected) - set(BENCHMARKS))
    if unknown:
        raise SystemExit(f"unknown benchmark(s) {unknown}; available: {list(BENCHMARKS)}")
    results: dict[str, object] = {}
    for name in selected:
        module = importlib.import_module(f"pymc_vcc.benchmarks.{name}")
        part = module.run(quick=args.quick)
        if not args.json:
            print(f"[{name}]")
            for key, value in part.items():
                print(f"  {key:32s} {value}")
        results.update(part)
    if args.json:
        print(json.dumps(results))
    return 0


def _demo(args: argparse.Namespace) -> int:
    from pymc_vcc.demo import run_demo

    run_demo(Path(args.out))
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pymc-vcc``, one sub-command per job."""
    parser = argparse.ArgumentParser(
        prog="pymc-vcc",
        description="Bayesian calibration of dynamic vapor-compression-cycle models.",
    )
    commands = parser.add_subparsers(dest="command", required=True)

    demo = commands.add_parser("demo", help="the main job: a small but real study")
    demo.add_argument("--out", default="results/demo", help="results folder")
    demo.set_defaults(handler=_demo)

    bench = commands.add_parser("bench", help="speed benchmarks")
    bench.add_argument("--json", action="store_true", help="print one JSON object last")
    bench.add_argument("--quick", action="store_true", help="fewer repetitions")
    bench.add_argument("--only", nargs="+", metavar="NAME", help="run only these benchmarks")
    bench.set_defaults(handler=_bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pymc-vcc`` console script."""
    args = build_parser().parse_args(argv)
    return args.handler(args)


if __name__ == "__main__":
    sys.exit(main())
