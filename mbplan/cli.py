"""The ``mbplan`` command line: ``mbplan --help`` lists the subcommands."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from mbplan.errors import InputError, MbplanError


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


def _bench_lie_ipm(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.lie_ipm import run

    methods = tuple(m.strip() for m in args.methods.split(",")) if args.methods else None
    run(
        Path(args.out),
        problem=args.problem,
        n=args.n,
        seed=args.seed,
        rho=args.rho,
        methods=methods,
        objective=args.objective,
        constants=args.constants,
        workers=args.workers,
        scheduler=args.scheduler,
        n_slow=args.n_slow,
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


def _bench_iiwa(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.iiwa_obstacle import run

    methods = tuple(m.strip() for m in args.methods.split(","))
    run(
        Path(args.out),
        n=args.n,
        seed=args.seed,
        methods=methods,
        N=args.horizon,
        workers=args.workers,
        scheduler=args.scheduler,
        warm_start=args.warm_start,
        constraint=args.constraint,
    )
    print((Path(args.out) / "results.md").read_text())
    return 0


def _plan(args: argparse.Namespace) -> int:
    from mbplan.planning.solve import plan
    from mbplan.results import save_npz
    from mbplan.tasks.obstacle import ObstacleTask, sample_obstacle_cases
    from mbplan.verification import verify

    if args.task != "obstacle":
        raise InputError(f"unknown task {args.task!r}; available: obstacle")
    fields = {
        "N": args.horizon,
        "warm_start": args.warm_start,
        "obstacle_constraint": args.constraint,
    }
    if args.seed is None:
        task = ObstacleTask(robot=args.robot, **fields)
    else:
        task = sample_obstacle_cases(args.robot, 1, args.seed, **fields)[0]
    result = plan(task, args.method, tol=args.tol, max_iter=args.max_iter)
    check = verify(task, result)
    print(
        f"{result.method}: {result.status} after {result.iterations} iterations, "
        f"{result.solve_time_s:.2f} s ({1e3 * result.time_per_iter_s:.1f} ms/iteration)"
    )
    print(
        f"verification: {'passed' if check.passed else 'FAILED'}; min obstacle clearance "
        f"{check.min_obstacle_distance_m:.3f} m, final goal error {check.final_goal_error_rad:.3f} rad"
        + "".join(f"\n  - {r}" for r in check.reasons)
    )
    if args.out:
        print(f"saved {save_npz(result, args.out)}")
    if args.viz or args.html:
        from mbplan.viz import replay

        print(replay([result], task, html=args.html, open_browser=args.viz))
    return 0 if result.success and check.passed else 1


def _replay(args: argparse.Namespace) -> int:
    from mbplan.viz import replay_main

    return replay_main(args.results, args.html, args.no_browser, robot=args.robot)


def _plot(args: argparse.Namespace) -> int:
    from mbplan.viz import plot_convergence, plot_trajectories, read_result

    results = [read_result(p) for p in args.results]
    labels = [f"{r.method} ({Path(p).name})" for r, p in zip(results, args.results, strict=True)]
    plot = {"convergence": plot_convergence, "trajectories": plot_trajectories}[args.kind]
    print(f"wrote {plot(results, args.out, labels=labels)}")
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

    plan = sub.add_parser("plan", help="plan a task with one method and verify the result")
    plan.add_argument("--robot", default="iiwa", help="robot name (see `mbplan robots`)")
    plan.add_argument("--task", default="obstacle", help="task family (obstacle)")
    plan.add_argument(
        "--seed",
        type=int,
        default=None,
        help="random start of the task sampler (default: the fixed demo start)",
    )
    plan.add_argument(
        "--method",
        default="ripm",
        help="ripm | mlgipm | ipopt | ipopt-no-restoration | fddp | csqp",
    )
    plan.add_argument("--horizon", type=int, default=40, help="number of steps N")
    plan.add_argument("--tol", type=float, default=1e-6, help="convergence tolerance")
    plan.add_argument("--max-iter", type=int, default=500, help="iteration limit")
    plan.add_argument("--out", default=None, help="write the result to this .npz file")
    plan.add_argument(
        "--warm-start",
        default="linear",
        choices=("linear", "via"),
        help="initial guess: linear joint interpolation (paper) or a collision-free via point",
    )
    _add_constraint_option(plan)
    plan.add_argument(
        "--viz", action="store_true", help="replay the result in meshcat (127.0.0.1) at the end"
    )
    plan.add_argument("--html", default=None, help="also write a self-contained replay page")
    plan.set_defaults(func=_plan)

    rep = sub.add_parser("replay", help="replay result.npz files in meshcat, side by side")
    rep.add_argument("results", nargs="+", help="one or more result .npz files")
    rep.add_argument("--html", default=None, help="write a self-contained page instead of serving")
    rep.add_argument(
        "--no-browser", action="store_true", help="do not open a browser (print the URL)"
    )
    rep.add_argument("--robot", default="iiwa", help="robot of the results (default iiwa)")
    rep.set_defaults(func=_replay)

    plot = sub.add_parser("plot", help="plot result.npz files (convergence or joint trajectories)")
    plot.add_argument("kind", choices=("convergence", "trajectories"), help="what to plot")
    plot.add_argument("results", nargs="+", help="result .npz files")
    plot.add_argument("--out", default="out/plot.png", help="output file (.png, .svg or .pdf)")
    plot.set_defaults(func=_plot)

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
    iiwa = bench_sub.add_parser(
        "iiwa-obstacle",
        help="maximal (RIPM) vs generalized (IPOPT) coordinates on seeded iiwa cases (Table III)",
    )
    iiwa.add_argument("--n", type=int, default=100, help="number of cases")
    iiwa.add_argument("--seed", type=int, default=0, help="seed of the case sampler")
    iiwa.add_argument(
        "--methods", default="ripm,ipopt,ipopt-no-restoration", help="comma-separated"
    )
    iiwa.add_argument("--horizon", type=int, default=40, help="number of steps N")
    iiwa.add_argument("--out", default="benchmarks/results/iiwa-obstacle", help="output directory")
    iiwa.add_argument(
        "--warm-start",
        default="linear",
        choices=("linear", "via"),
        help="initial guess of every method: linear joint interpolation (paper) or a collision-free via point",
    )
    _add_constraint_option(iiwa)
    _add_pool_options(iiwa)
    iiwa.set_defaults(func=_bench_iiwa)
    lie = bench_sub.add_parser(
        "lie-ipm",
        help="MLG-IPM vs Lai-Yoshise, RIPM, IPOPT on the MLG-IPM paper's SO(7)/SL(7) problems",
    )
    lie.add_argument("--problem", default="so7", choices=("so7", "sl7"), help="(10) or (11)")
    lie.add_argument("--n", type=int, default=1000, help="number of instances")
    lie.add_argument("--seed", type=int, default=0, help="seed of the instance sampler")
    lie.add_argument(
        "--rho", type=float, default=0.0, help="inexact term ‖ρ_k‖ = rho·‖F_k‖ (0, 0.01, 0.001)"
    )
    lie.add_argument("--methods", default=None, help="comma-separated (default: all that apply)")
    lie.add_argument(
        "--objective", default="squared", choices=("squared", "literal"), help="form of (10)"
    )
    lie.add_argument(
        "--constants",
        default="rendered",
        choices=("rendered", "alt-text"),
        help="0.5/0.3/0.2 (rendered) or 5/3/2 (LaTeX alt-text)",
    )
    lie.add_argument(
        "--n-slow",
        type=int,
        default=None,
        help="fewer instances for the slow baselines (lai-yoshise, ripm, ipopt)",
    )
    lie.add_argument(
        "--out", default="benchmarks/results/lie-ipm/so7-rho0", help="output directory"
    )
    _add_pool_options(lie)
    lie.set_defaults(func=_bench_lie_ipm)
    return parser


def _add_constraint_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--constraint",
        default="com",
        choices=("com", "distance"),
        help="obstacle constraint: link COMs outside the cylinder (paper eq. 62) or coal "
        "distances between link collision geometry and obstacles >= margin",
    )


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
