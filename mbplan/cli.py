"""The ``mbplan`` command line: ``mbplan --help`` lists the subcommands."""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from mbplan.cli_support import Parser, integer, integer_list, names, parse, real, run_command
from mbplan.errors import InputError, WarmStartWarning
from mbplan.validation import output_dir, output_file


def _bench_engine(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.engine_scaling import run

    summary = run(output_dir(args.out, "--out"), knots=args.knots, seed=args.seed)
    print((Path(args.out) / "results.md").read_text())
    return 0 if summary["rows"] else 1


def _bench_drone(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.drone_docking import run

    run(
        output_dir(args.out, "--out"),
        n=args.n,
        seed=args.seed,
        tol=args.tol,
        methods=args.methods,
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
        output_dir(args.out, "--out"),
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
    p.add_argument(
        "--workers", type=integer(1), default=1, help="local worker processes (default 1)"
    )
    p.add_argument("--scheduler", default=None, help="Dask scheduler address (runs on the cluster)")


def _bench_chain(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.chain_scaling import run

    run(output_dir(args.out, "--out"), N=args.horizon)
    print((Path(args.out) / "results.md").read_text())
    return 0


def _validate_dynamics(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.validate_dynamics import run

    out = output_dir(args.out, "--out")
    summary = run(args.robot, args.seed, out, T=args.duration)
    print((Path(args.out) / "results.md").read_text())
    return 0 if summary["all_targets_met"] else 1


def _bench_iiwa(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.iiwa_obstacle import run

    run(
        output_dir(args.out, "--out"),
        n=args.n,
        seed=args.seed,
        methods=args.methods,
        N=args.horizon,
        workers=args.workers,
        scheduler=args.scheduler,
        warm_start=args.warm_start,
        constraint=args.constraint,
    )
    print((Path(args.out) / "results.md").read_text())
    return 0


def _bench_ilqr(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.ilqr.bench import METHODS, run
    from mbplan.benchmarks.ilqr.scenarios import SCENARIOS

    scenarios = SCENARIOS if args.scenario == "all" else (args.scenario,)
    methods = (
        METHODS if args.methods == "all" else tuple(m.strip() for m in args.methods.split(","))
    )
    out = output_dir(args.out, "--out")
    run(out, scenarios, methods, repeats=args.repeats, lgvi=not args.no_lgvi)
    print((Path(args.out) / "results.md").read_text())
    return 0


def _bench_speed(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.speed import run

    out = output_dir(args.out, "--out")
    run(
        out,
        n_iiwa=args.n_iiwa,
        n_drone=args.n_drone,
        links=tuple(args.links),
        seed=args.seed,
        workers=args.workers,
        scheduler=args.scheduler,
    )
    print((Path(args.out) / "results.md").read_text())
    return 0


_BUILTIN_DEFAULTS = {
    "robot": "iiwa",
    "task": "obstacle",
    "method": "ripm",
    "horizon": 40,
    "tol": 1e-6,
    "max_iter": 500,
    "warm_start": "linear",
    "constraint": "com",
}


def _builtin_task(args: argparse.Namespace) -> tuple[Any, Callable[[], Any]]:
    """The OCP of ``mbplan plan --robot iiwa ...`` and a function planning it."""
    from mbplan.paper import iiwa_obstacle, iiwa_obstacle_cases
    from mbplan.planning.solve import METHODS, plan

    for key, value in _BUILTIN_DEFAULTS.items():
        if getattr(args, key) is None:
            setattr(args, key, value)
    if args.task != "obstacle":
        raise InputError(f"unknown task {args.task!r}; available: obstacle")
    if args.method not in METHODS:
        raise InputError(f"unknown method {args.method!r}; choose from {', '.join(METHODS)}")
    if args.robot != "iiwa":
        from mbplan.ocp.robot import load_robot

        load_robot(args.robot)  # an unknown robot is named as such
        raise InputError(
            f"the obstacle task is defined for the iiwa; for {args.robot!r} write a task file "
            "(mbplan plan TASK.toml, README: Task files) or build an mbplan.OCP"
        )
    if args.seed is None:
        problem = iiwa_obstacle(N=args.horizon, constraint=args.constraint)
    else:
        problem = iiwa_obstacle_cases(1, args.seed, N=args.horizon, constraint=args.constraint)[0]
    return problem, lambda: plan(
        problem, args.method, warm_start=args.warm_start, tol=args.tol, max_iter=args.max_iter
    )


def _task_file(args: argparse.Namespace) -> tuple[Any, Callable[[], Any]]:
    """The OCP of ``mbplan plan TASK.toml``, the flags overriding the file, and its planner."""
    from mbplan.taskfile import load_task
    from mbplan.taskfile.toml_table import parse_value

    for flag in ("robot", "task", "seed"):
        if getattr(args, flag) is not None:
            raise InputError(f"--{flag} is not used with a task file (the file names the robot)")
    overrides = [
        (key, getattr(args, dest), flag)
        for dest, key, flag in _TASK_FLAGS
        if getattr(args, dest) is not None
    ]
    for item in args.set or ():
        key, sep, text = item.partition("=")
        if not sep:
            raise InputError(f"--set: expected TABLE.KEY=VALUE, got {item!r}")
        overrides.append((key.strip(), parse_value(text.strip(), f"--set {key}"), "--set"))
    task = load_task(args.task_file, overrides)
    task.ocp.check()
    return task.ocp, task.plan


_TASK_FLAGS = (  # flag dest, task-file key, flag name
    ("method", "solver.method", "--method"),
    ("horizon", "horizon.N", "--horizon"),
    ("dt", "horizon.dt", "--dt"),
    ("tol", "solver.tol", "--tol"),
    ("max_iter", "solver.max_iter", "--max-iter"),
    ("warm_start", "solver.warm_start", "--warm-start"),
    ("constraint", "constraints.obstacle", "--constraint"),
)


def _plan(args: argparse.Namespace) -> int:
    from mbplan.results import save_npz
    from mbplan.verification import verify

    out = output_file(args.out, (".npz",), "--out") if args.out else None
    html = output_file(args.html, (".html", ".htm"), "--html") if args.html else None
    if args.strict_warm_start:
        warnings.simplefilter("error", WarmStartWarning)
    if args.task_file is not None:
        problem, solve = _task_file(args)
    else:
        if args.dt is not None or args.set:
            raise InputError("--dt and --set apply to a task file (mbplan plan TASK.toml ...)")
        problem, solve = _builtin_task(args)
    result = solve()
    check = verify(problem, result)
    print(
        f"{result.method}: {result.status} after {result.iterations} iterations, "
        f"{result.solve_time_s:.2f} s ({1e3 * result.time_per_iter_s:.1f} ms/iteration)"
    )
    goals = ", ".join(f"{k} {v:.3g}" for k, v in {**check.violations, **check.goal_errors}.items())
    soft = f", final goal error {check.final_goal_error_rad:.3f} rad" if check.goal_errors else ""
    print(
        f"verification: {'passed' if check.passed else 'FAILED'}; min obstacle clearance "
        f"{check.min_obstacle_distance_m:.3f} m{soft}"
        + (f"\n  constraint violations / goal errors: {goals}" if args.task_file else "")
        + "".join(f"\n  - {r}" for r in check.reasons)
    )
    code = 0 if result.success and check.passed else 1
    if out:
        print(f"saved {save_npz(result, out)}")
    if html:
        from mbplan.viz import static_html

        print(f"wrote {static_html([result], html, problem)}")
    if args.viz:
        from mbplan.viz import serve

        serve([result], problem)
    return code


def _replay(args: argparse.Namespace) -> int:
    from mbplan.viz import replay_main

    html = output_file(args.html, (".html", ".htm"), "--html") if args.html else None
    return replay_main(args.results, html, args.no_browser, robot=args.robot, colors=args.colors)


def _plot(args: argparse.Namespace) -> int:
    from mbplan.viz import plot_convergence, plot_trajectories, read_result

    output_file(args.out, (".png", ".svg", ".pdf"), "--out")
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
    parser = Parser(
        prog="mbplan",
        description="Trajectory optimization of multi-body robots on matrix Lie groups "
        "(maximal coordinates on SO(3)×R³, LGVI dynamics, Riemannian interior point).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    plan = sub.add_parser(
        "plan",
        help="plan a task file (or the built-in iiwa task) with one method and verify the result",
    )
    plan.add_argument(
        "task_file",
        nargs="?",
        default=None,
        metavar="TASK.toml",
        help="a task file (README: Task files); the flags below override its keys",
    )
    plan.add_argument(
        "--robot", default=None, help="robot of the built-in task (default iiwa; no task file)"
    )
    plan.add_argument("--task", default=None, help="built-in task family (obstacle)")
    plan.add_argument(
        "--seed",
        type=integer(0),
        default=None,
        help="random start of the task sampler (default: the fixed demo start)",
    )
    plan.add_argument(
        "--method",
        default=None,
        help="ripm (default) | mlgipm | ipopt | ipopt-no-restoration | fddp | csqp",
    )
    plan.add_argument(
        "--horizon", type=integer(2), default=None, help="number of steps N (default 40)"
    )
    plan.add_argument("--dt", type=real(), default=None, help="time step [s] (task files)")
    plan.add_argument(
        "--tol", type=real(), default=None, help="convergence tolerance (default 1e-6)"
    )
    plan.add_argument(
        "--max-iter", type=integer(0), default=None, help="iteration limit (default 500)"
    )
    plan.add_argument("--out", default=None, help="write the result to this .npz file")
    plan.add_argument(
        "--warm-start",
        default=None,
        choices=("linear", "via"),
        help="initial guess: linear joint interpolation (paper; the built-in task's default) or "
        "a collision-free via point (a task file's default)",
    )
    plan.add_argument(
        "--set",
        action="append",
        metavar="TABLE.KEY=VALUE",
        help="override a key of the task file (a TOML value), e.g. --set "
        "'robot.lock=[\"panda_finger_joint1\"]'; repeatable",
    )
    plan.add_argument(
        "--strict-warm-start",
        action="store_true",
        help='fail (exit 2) instead of warning when "via" finds no collision-free via point',
    )
    _add_constraint_option(plan, default=None)
    plan.add_argument(
        "--viz",
        action="store_true",
        help="replay the result in meshcat (127.0.0.1) at the end, serving until Ctrl-C",
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
    rep.add_argument(
        "--colors",
        choices=("formulation", "materials"),
        default="formulation",
        help="tint each robot by its formulation (default) or keep the meshes' own materials",
    )
    rep.set_defaults(func=_replay)

    plot = sub.add_parser("plot", help="plot result.npz files (convergence or joint trajectories)")
    plot.add_argument("kind", choices=("convergence", "trajectories"), help="what to plot")
    plot.add_argument("results", nargs="+", help="result .npz files")
    plot.add_argument("--out", default="out/plot.png", help="output file (.png, .svg or .pdf)")
    plot.set_defaults(func=_plot)

    validate = sub.add_parser(
        "validate-dynamics",
        help="simulate the maximal-coordinate LGVI on a smooth motion, without and with joint "
        "damping, against Pinocchio (ABA, fine RK4): observed order and error constant",
    )
    validate.add_argument(
        "--robot",
        type=names,
        default=None,
        help="comma-separated robot names (see `mbplan robots`) or URDF paths (default: all robots)",
    )
    validate.add_argument(
        "--seed", type=integer(0), default=0, help="seed of the start, motion and torques"
    )
    validate.add_argument("--duration", type=real(), default=0.4, help="simulated time [s]")
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
    engine.add_argument(
        "--out", default="out/bench/engine", help="output directory (default out/bench/engine)"
    )
    engine.add_argument(
        "--knots",
        type=integer_list(1),
        default=(1, 10, 100, 1000, 10000),
        help="comma-separated knot counts",
    )
    engine.add_argument(
        "--seed", type=integer(0), default=0, help="random seed of the evaluation points"
    )
    engine.set_defaults(func=_bench_engine)
    chain = bench_sub.add_parser(
        "chain", help="0th/1st/2nd-order evaluation time of a serial chain of 1..64 bodies (Fig. 6)"
    )
    chain.add_argument(
        "--out",
        default="out/bench/chain-scaling",
        help="output directory (default out/bench/chain-scaling)",
    )
    chain.add_argument("--horizon", type=integer(1), default=40, help="number of knots N")
    chain.set_defaults(func=_bench_chain)
    drone = bench_sub.add_parser(
        "drone-docking",
        help="RIPM vs quaternion IPOPT on seeded drone docking cases (Table II, Fig. 4)",
    )
    drone.add_argument("--n", type=integer(1), default=100, help="number of cases")
    drone.add_argument("--seed", type=integer(0), default=0, help="seed of the case sampler")
    drone.add_argument(
        "--tol", type=real(), default=1e-6, help="convergence tolerance of every method"
    )
    drone.add_argument(
        "--methods",
        type=names,
        default=("ripm", "ripm-input-limits", "ipopt-quaternion"),
        help="comma-separated",
    )
    drone.add_argument(
        "--out",
        default="out/bench/drone-docking",
        help="output directory (default out/bench/drone-docking)",
    )
    drone.add_argument("--no-scaling", action="store_true", help="skip the N=40 vs N=160 timing")
    _add_pool_options(drone)
    drone.set_defaults(func=_bench_drone)
    iiwa = bench_sub.add_parser(
        "iiwa-obstacle",
        help="maximal (RIPM) vs generalized (IPOPT) coordinates on seeded iiwa cases (Table III)",
    )
    iiwa.add_argument("--n", type=integer(1), default=100, help="number of cases")
    iiwa.add_argument("--seed", type=integer(0), default=0, help="seed of the case sampler")
    iiwa.add_argument(
        "--methods",
        type=names,
        default=("ripm", "ipopt", "ipopt-no-restoration"),
        help="comma-separated: ripm, ipopt, ipopt-no-restoration, fddp, csqp",
    )
    iiwa.add_argument("--horizon", type=integer(2), default=40, help="number of steps N")
    iiwa.add_argument(
        "--out",
        default="out/bench/iiwa-obstacle",
        help="output directory (default out/bench/iiwa-obstacle)",
    )
    iiwa.add_argument(
        "--warm-start",
        default="linear",
        choices=("linear", "via"),
        help="initial guess of every method: linear joint interpolation (paper) or a collision-free via point",
    )
    _add_constraint_option(iiwa)
    _add_pool_options(iiwa)
    iiwa.set_defaults(func=_bench_iiwa)
    ilqr = bench_sub.add_parser(
        "ilqr",
        help="SS-/MS-iLQR vs embedded IPOPT and RIPM on the thesis' scenarios (Tables 4-2, 4-3)",
    )
    ilqr.add_argument(
        "--scenario",
        default="all",
        choices=("so3-tracking", "se3-tracking", "pendulum", "drone", "all"),
    )
    ilqr.add_argument(
        "--methods",
        default="all",
        help="comma-separated: ss-ilqr, ms-ilqr, ms-ddp, ipopt-quaternion, ipopt-embedded-dynamics, "
        "ipopt-embedded-manifold, fddp, ripm (default all)",
    )
    ilqr.add_argument(
        "--repeats", type=integer(1), default=3, help="timed solves per method (median)"
    )
    ilqr.add_argument(
        "--no-lgvi", action="store_true", help="skip the LGVI variants of so3-tracking, pendulum"
    )
    ilqr.add_argument("--out", default="out/bench/ilqr", help="output directory")
    ilqr.set_defaults(func=_bench_ilqr)
    speed = bench_sub.add_parser(
        "speed",
        help="RIPM vs every baseline on drone, iiwa (com) and chain reach, with the RIPM profile",
    )
    speed.add_argument("--n-iiwa", type=integer(1), default=100, help="iiwa cases (default 100)")
    speed.add_argument("--n-drone", type=integer(1), default=100, help="drone cases (default 100)")
    speed.add_argument(
        "--links",
        type=integer_list(1),
        default=(4, 8, 16, 32, 64),
        help="chain sizes (comma-separated)",
    )
    speed.add_argument("--seed", type=integer(0), default=0)
    speed.add_argument("--out", default="out/bench/speed", help="output directory")
    _add_pool_options(speed)
    speed.set_defaults(func=_bench_speed)
    lie = bench_sub.add_parser(
        "lie-ipm",
        help="MLG-IPM vs Lai-Yoshise, RIPM, IPOPT on the MLG-IPM paper's SO(7)/SL(7) problems",
    )
    lie.add_argument("--problem", default="so7", choices=("so7", "sl7"), help="(10) or (11)")
    lie.add_argument("--n", type=integer(1), default=1000, help="number of instances")
    lie.add_argument("--seed", type=integer(0), default=0, help="seed of the instance sampler")
    lie.add_argument(
        "--rho",
        type=real(positive=False),
        default=0.0,
        help="inexact term ‖ρ_k‖ = rho·‖F_k‖ (0, 0.01, 0.001)",
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
        type=integer(1),
        default=None,
        help="fewer instances for the slow baselines (lai-yoshise, ripm, ipopt)",
    )
    lie.add_argument("--out", default="out/bench/lie-ipm", help="output directory")
    _add_pool_options(lie)
    lie.set_defaults(func=_bench_lie_ipm)
    return parser


def _add_constraint_option(parser: argparse.ArgumentParser, default: str | None = "com") -> None:
    parser.add_argument(
        "--constraint",
        default=default,
        choices=("com", "distance"),
        help="obstacle constraint: link COMs outside the cylinder (paper eq. 62) or coal "
        "distances between link collision geometry and obstacles >= margin",
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parse(parser, argv)
    if isinstance(args, int):
        return args
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    return run_command(lambda: args.func(args))


if __name__ == "__main__":
    sys.exit(main())
