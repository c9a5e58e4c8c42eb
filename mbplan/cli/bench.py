"""``mbplan bench …``: one subcommand per benchmark, each writing results.md/JSON/plots."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from mbplan.cli.support import add_constraint_option, integer, integer_list, names, real
from mbplan.validation import output_dir


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
    from mbplan.tasks.ilqr import SCENARIOS

    scenarios = SCENARIOS if args.scenario == "all" else (args.scenario,)
    methods = (
        METHODS if args.methods == "all" else tuple(m.strip() for m in args.methods.split(","))
    )
    out = output_dir(args.out, "--out")
    run(out, scenarios, methods, repeats=args.repeats, lgvi=not args.no_lgvi)
    print((Path(args.out) / "results.md").read_text())
    return 0


def _bench_speed(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.speed import run, run_cold

    out = output_dir(args.out, "--out")
    if args.cold_only:
        run_cold(out)
        print((Path(args.out) / "results.md").read_text())
        return 0
    run(
        out,
        n_iiwa=args.n_iiwa,
        n_iiwa_distance=args.n_iiwa_distance,
        n_drone=args.n_drone,
        links=tuple(args.links),
        seed=args.seed,
        workers=args.workers,
        scheduler=args.scheduler,
    )
    print((Path(args.out) / "results.md").read_text())
    return 0


def _bench_suite(module: str) -> Callable[[argparse.Namespace], int]:
    """The command running the :class:`~mbplan.benchmarks.families.Suite` of ``module``."""

    def bench(args: argparse.Namespace) -> int:
        from importlib import import_module

        from mbplan.benchmarks.families import run

        suite = import_module(module).SUITE
        run(
            suite,
            output_dir(args.out, "--out"),
            n=args.n,
            seed=args.seed,
            methods=args.methods,
            families=getattr(args, suite.family_flag),
            tol=args.tol,
            max_iter=args.max_iter,
            workers=args.workers,
            scheduler=args.scheduler,
        )
        print((Path(args.out) / "results.md").read_text())
        return 0

    return bench


def _add_suite_options(
    parser: argparse.ArgumentParser, n: int, families: tuple[str, ...], flag: str, tol: float
) -> None:
    """The options of a family benchmark (:mod:`mbplan.benchmarks.families`)."""
    parser.add_argument("--n", type=integer(1), default=n, help="cases per family")
    parser.add_argument("--seed", type=integer(0), default=0, help="seed of the drawn cases")
    parser.add_argument(
        "--methods", type=names, default=("ripm", "ipopt"), help="comma-separated (ipopt: baseline)"
    )
    parser.add_argument(
        f"--{flag}", type=names, default=families, help=f"comma-separated: {', '.join(families)}"
    )
    parser.add_argument(
        "--tol", type=real(), default=tol, help="convergence tolerance of every method"
    )
    parser.add_argument(
        "--max-iter", type=integer(1), default=500, help="iteration limit of every method"
    )


def add_bench_parser(sub: argparse._SubParsersAction) -> None:
    """The ``bench`` subcommand of the ``mbplan`` parser, one sub-subcommand per benchmark."""
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
    add_constraint_option(iiwa)
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
        help="RIPM vs every baseline on drone, iiwa (com, distance) and chain reach (without and "
        "with an obstacle), with the RIPM profile",
    )
    speed.add_argument("--n-iiwa", type=integer(1), default=100, help="iiwa cases (default 100)")
    speed.add_argument(
        "--n-iiwa-distance",
        type=integer(0),
        default=None,
        help="iiwa cases with coal distance constraints (default: --n-iiwa)",
    )
    speed.add_argument("--n-drone", type=integer(1), default=100, help="drone cases (default 100)")
    speed.add_argument(
        "--links",
        type=integer_list(1),
        default=(4, 8, 16, 32, 64),
        help="chain sizes (comma-separated)",
    )
    speed.add_argument("--seed", type=integer(0), default=0)
    speed.add_argument("--out", default="out/bench/speed", help="output directory")
    speed.add_argument(
        "--cold-only",
        action="store_true",
        help="only the cold-start section (each task planned in a new process beside the same "
        "plan warm), added to the summary already in --out",
    )
    _add_pool_options(speed)
    speed.set_defaults(func=_bench_speed)
    loops = bench_sub.add_parser(
        "loops",
        help="RIPM vs IPOPT on the closed-loop mechanisms (fourbar, delta, two_arm_carry): the "
        "example task (case 0) and seeded randomizations of it",
    )
    _add_suite_options(loops, 10, ("fourbar", "delta", "two_arm_carry"), "mechanisms", 1e-8)
    loops.add_argument("--out", default="out/bench/loops", help="output directory")
    _add_pool_options(loops)
    loops.set_defaults(func=_bench_suite("mbplan.benchmarks.loops"))
    floating = bench_sub.add_parser(
        "floating",
        help="RIPM vs IPOPT on floating-base robots in free flight (solo12, anymal, go2, "
        "talos_legs): seeded joint targets",
    )
    _add_suite_options(floating, 10, ("solo12", "anymal", "go2", "talos_legs"), "robots", 1e-6)
    floating.add_argument("--out", default="out/bench/floating", help="output directory")
    _add_pool_options(floating)
    floating.set_defaults(func=_bench_suite("mbplan.benchmarks.floating"))
    from mbplan.tasks.locomotion import FAMILIES

    locomotion = bench_sub.add_parser(
        "locomotion",
        help="RIPM vs IPOPT on gaits with hard contacts (solo12 and anymal: walk, trot, pace, "
        "bound, jump on Crocoddyl's schedules; talos_legs: walk on soles): nominal and seeded "
        "steps",
    )
    _add_suite_options(locomotion, 20, tuple(FAMILIES), "gaits", 1e-6)
    locomotion.add_argument("--out", default="out/bench/locomotion", help="output directory")
    _add_pool_options(locomotion)
    locomotion.set_defaults(func=_bench_suite("mbplan.benchmarks.locomotion"))
    robustness = bench_sub.add_parser(
        "robustness",
        help="RIPM vs IPOPT on seeded families of hard tasks (graded chains, mesh arms among "
        "boxes, goals near limits, at rest, near singular, paper tasks from the linear warm "
        "start), with a failure table",
    )
    _add_suite_options(
        robustness,
        20,
        ("graded_chain", "arm_boxes", "near_limits", "rest_goal", "near_singular", "paper_linear"),
        "families",
        1e-6,
    )
    robustness.add_argument("--out", default="out/bench/robustness", help="output directory")
    _add_pool_options(robustness)
    robustness.set_defaults(func=_bench_suite("mbplan.benchmarks.robustness"))
    scenes = bench_sub.add_parser(
        "scenes",
        help="RIPM vs IPOPT among obstacles with coal distances (UR5 shelf, panda between boxes, "
        "iiwa, a sweep of mesh-collision arms among random boxes), with the RIPM's time split",
    )
    _add_suite_options(
        scenes, 100, ("ur5_shelf", "panda_boxes", "iiwa_distance", "mesh_sweep"), "families", 1e-6
    )
    scenes.add_argument("--out", default="out/bench/scenes", help="output directory")
    _add_pool_options(scenes)
    scenes.set_defaults(func=_bench_suite("mbplan.benchmarks.scenes"))
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
