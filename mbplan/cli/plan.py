"""``mbplan plan``: a task file (or the built-in iiwa task) planned with one method, verified,
saved and optionally replayed."""

from __future__ import annotations

import argparse
import math
import warnings
from collections.abc import Callable
from typing import Any

from mbplan.cli.support import add_constraint_option, integer, real
from mbplan.errors import InputError, WarmStartWarning
from mbplan.validation import output_file

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
    from mbplan.planning.solve import METHODS, plan
    from mbplan.tasks.paper import iiwa_obstacle, iiwa_obstacle_cases

    for key, value in _BUILTIN_DEFAULTS.items():
        if getattr(args, key) is None:
            setattr(args, key, value)
    if args.task != "obstacle":
        raise InputError(f"unknown task {args.task!r}; available: obstacle")
    if args.method not in METHODS:
        raise InputError(f"unknown method {args.method!r}; choose from {', '.join(METHODS)}")
    if args.robot != "iiwa":
        from mbplan.robots.robot import load_robot

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
    from mbplan.planning.solve import check_start
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
    check_start(task.ocp)
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
        + (
            f"; kernels compiled or loaded in {result.compile_time_s:.2f} s"
            if result.compile_time_s
            else ""
        )
    )
    goals = ", ".join(f"{k} {v:.3g}" for k, v in {**check.violations, **check.goal_errors}.items())
    soft = f", final goal error {check.final_goal_error_rad:.3f} rad" if check.goal_errors else ""
    kept = "" if math.isnan(check.margin_kept) else f" ({check.margin_kept:.0%} of the margin)"
    if getattr(problem.robot, "loops", ()):
        soft += f", loop closure residual {check.closure_residual:.2g}"
    print(
        f"verification: {'passed' if check.passed else 'FAILED'}; min obstacle clearance "
        f"{check.min_obstacle_distance_m:.3f} m along the motion{kept}{soft}"
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


def add_plan_parser(sub: argparse._SubParsersAction) -> None:
    """The ``plan`` subcommand of the ``mbplan`` parser."""
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
    add_constraint_option(plan, default=None)
    plan.add_argument(
        "--viz",
        action="store_true",
        help="replay the result in meshcat (127.0.0.1) at the end, serving until Ctrl-C",
    )
    plan.add_argument("--html", default=None, help="also write a self-contained replay page")
    plan.set_defaults(func=_plan)
