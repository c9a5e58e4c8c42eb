"""The ``mbplan`` command line: ``mbplan --help`` lists the subcommands."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from mbplan.errors import MbplanError


def _bench_engine(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.engine_scaling import run

    knots = tuple(int(k) for k in args.knots.split(","))
    summary = run(Path(args.out), knots=knots, seed=args.seed)
    print((Path(args.out) / "results.md").read_text())
    return 0 if summary["rows"] else 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mbplan",
        description="Trajectory optimization of multi-body robots on matrix Lie groups "
        "(maximal coordinates on SO(3)×R³, LGVI dynamics, Riemannian interior point).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    bench = sub.add_parser(
        "bench", help="run a benchmark and write its results (JSON, markdown, plot)"
    )
    bench_sub = bench.add_subparsers(dest="benchmark", metavar="BENCHMARK")
    engine = bench_sub.add_parser(
        "engine",
        help="value/Jacobian/Hessian of the rigid-body LGVI step for 1..10⁴ knots, interpreted vs JIT",
    )
    engine.add_argument("--out", default="benchmarks/results/engine", help="output directory")
    engine.add_argument(
        "--knots", default="1,10,100,1000,10000", help="comma-separated knot counts"
    )
    engine.add_argument("--seed", type=int, default=0, help="random seed of the evaluation points")
    engine.set_defaults(func=_bench_engine)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    try:
        return int(args.func(args))
    except MbplanError as exc:
        print(f"mbplan: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
