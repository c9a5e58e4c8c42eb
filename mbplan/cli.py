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


def _bench_drone(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.drone_docking import run

    methods = tuple(m.strip() for m in args.methods.split(","))
    run(
        Path(args.out),
        n=args.n,
        seed=args.seed,
        tol=args.tol,
        methods=methods,
        workers=args.workers,
        scheduler=args.scheduler,
        scaling=not args.no_scaling,
    )
    print((Path(args.out) / "results.md").read_text())
    return 0


def _add_pool_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=int, default=1, help="local worker processes (default 1)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address (runs on the cluster)")


def _bench_chain(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.chain_scaling import run

    run(Path(args.out), N=args.horizon)
    print((Path(args.out) / "results.md").read_text())
    return 0


def _validate_dynamics(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.validate_dynamics import run

    run(args.robot, args.seed, Path(args.out), T=args.duration, long_steps=args.long_steps)
    print((Path(args.out) / "results.md").read_text())
    return 0


def _robots(args: argparse.Namespace) -> int:
    from mbplan.robots import available_robots

    for name in available_robots():
        print(name)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mbplan",
        description="Trajectory optimization of multi-body robots on matrix Lie groups "
        "(maximal coordinates on SO(3)×R³, LGVI dynamics, Riemannian interior point).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    validate = sub.add_parser(
        "validate-dynamics",
        help="simulate the maximal-coordinate LGVI and compare with Pinocchio (ABA, fine RK4)",
    )
    validate.add_argument(
        "--robot", default="iiwa", help="robot name (see `mbplan robots`) or URDF path"
    )
    validate.add_argument(
        "--seed", type=int, default=0, help="seed of the initial state and torques"
    )
    validate.add_argument("--duration", type=float, default=1.0, help="simulated time [s]")
    validate.add_argument(
        "--long-steps", type=int, default=10_000, help="steps of the long energy run"
    )
    validate.add_argument("--out", default="out/validate-dynamics", help="output directory")
    validate.set_defaults(func=_validate_dynamics)

    robots = sub.add_parser("robots", help="list the robot names mbplan can load")
    robots.set_defaults(func=_robots)

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
    chain = bench_sub.add_parser(
        "chain", help="0th/1st/2nd-order evaluation time of a serial chain of 1..64 bodies (Fig. 6)"
    )
    chain.add_argument("--out", default="benchmarks/results/chain-scaling", help="output directory")
    chain.add_argument("--horizon", type=int, default=40, help="number of knots N")
    chain.set_defaults(func=_bench_chain)
    drone = bench_sub.add_parser(
        "drone-docking",
        help="RIPM vs quaternion IPOPT on seeded drone docking cases (Table II, Fig. 4)",
    )
    drone.add_argument("--n", type=int, default=100, help="number of cases")
    drone.add_argument("--seed", type=int, default=0, help="seed of the case sampler")
    drone.add_argument(
        "--tol", type=float, default=1e-6, help="convergence tolerance of every method"
    )
    drone.add_argument(
        "--methods", default="ripm,ripm-input-limits,ipopt-quaternion", help="comma-separated"
    )
    drone.add_argument("--out", default="benchmarks/results/drone-docking", help="output directory")
    drone.add_argument("--no-scaling", action="store_true", help="skip the N=40 vs N=160 timing")
    _add_pool_options(drone)
    drone.set_defaults(func=_bench_drone)
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
