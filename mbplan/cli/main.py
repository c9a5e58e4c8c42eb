"""The ``mbplan`` command line: ``mbplan --help`` lists the subcommands."""

from __future__ import annotations

import argparse
import gc
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from mbplan.cli.bench import add_bench_parser
from mbplan.cli.plan import add_plan_parser
from mbplan.cli.support import Parser, integer, names, parse, real, run_command
from mbplan.cli.warmup import add_warmup_parser
from mbplan.validation import output_dir, output_file


def _validate_dynamics(args: argparse.Namespace) -> int:
    from mbplan.benchmarks.validate_dynamics import run

    out = output_dir(args.out, "--out")
    summary = run(args.robot, args.seed, out, T=args.duration)
    print((Path(args.out) / "results.md").read_text())
    return 0 if summary["all_targets_met"] else 1


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
    from mbplan.robots import MECHANISMS, available_floating, available_robots, load_robot

    floating = set(available_floating())
    for name in available_robots():
        if name in floating:
            joints = len(load_robot(name).joint_names)
            print(f"{name}  (floating base: a free body and {joints} joints)")
            continue
        if name not in MECHANISMS:
            print(name)
            continue
        robot = load_robot(name)
        rows = sum(loop.dim for loop in robot.loops)
        actuated = [n for n in robot.model.names[1:] if n not in robot.passive]
        print(
            f"{name}  ({robot.nv} joints, {rows} closure rows: {robot.nv - rows} dof; actuated: "
            f"{', '.join(actuated)})"
        )
        for loop in robot.loops:
            print(f"    {loop.describe()}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="mbplan",
        description="Trajectory optimization of multi-body robots on matrix Lie groups "
        "(maximal coordinates on SO(3)×R³, LGVI dynamics, Riemannian interior point).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    add_plan_parser(sub)

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
        help="comma-separated robot names (see `mbplan robots`), URDF or MJCF paths (MJCF "
        "<equality> closures: against Pinocchio's constrained dynamics; default: all robots)",
    )
    validate.add_argument(
        "--seed", type=integer(0), default=0, help="seed of the start, motion and torques"
    )
    validate.add_argument("--duration", type=real(), default=0.4, help="simulated time [s]")
    validate.add_argument("--out", default="out/validate-dynamics", help="output directory")
    validate.set_defaults(func=_validate_dynamics)

    robots = sub.add_parser("robots", help="list the robot names mbplan can load")
    robots.set_defaults(func=_robots)

    add_warmup_parser(sub)
    add_bench_parser(sub)
    return parser


def console() -> NoReturn:
    """The ``mbplan`` program: :func:`main` of the command line, then exit with its code.

    The objects alive once the package is imported (hundreds of thousands: numba's type
    system, SciPy, CasADi, Pinocchio) and those alive at the end are moved out of the garbage
    collector's reach (:func:`gc.freeze`): the collections during the command and at the
    interpreter's exit would otherwise traverse them all, ~0.1 s and ~0.4 s of a ~2 s plan.
    Objects created during the command are collected as usual."""
    gc.freeze()
    code = main()
    gc.freeze()
    sys.exit(code)


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
    console()
