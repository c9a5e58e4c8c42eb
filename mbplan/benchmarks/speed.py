"""Speed of the RIPM against the baselines on its own tasks, with a per-iteration profile.

Task construction is one small function per task (:func:`iiwa_task`, :func:`drone_task`,
:func:`chain_task`) so that it can move onto another task API without touching the rest.
"""

from __future__ import annotations

import functools
import tempfile
import time
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from mbplan.solvers import RIPMOptions, RIPMResult, solve_ripm
from mbplan.solvers import linear_solver as ls

# ------------------------------------------------------------------------------- tasks


@functools.cache
def _iiwa_cases(n: int, seed: int, constraint: str) -> list:
    from mbplan.tasks.obstacle import sample_obstacle_cases

    return sample_obstacle_cases(
        "iiwa", n, seed, N=40, warm_start="via", obstacle_constraint=constraint
    )


def iiwa_task(index: int, n: int = 100, seed: int = 0, constraint: str = "com"):
    """iiwa obstacle case ``index`` of ``n`` (via warm start, N = 40) as an ObstacleTask."""
    return _iiwa_cases(n, seed, constraint)[index]


def manipulator_ripm_problem(task) -> tuple[Any, Any]:
    """The RIPM's problem and warm start for an ObstacleTask (as ``plan_maximal`` builds them)."""
    from mbplan.engine.jit import jit_available
    from mbplan.multibody import maximal_model
    from mbplan.planning.manipulator import task_ocp
    from mbplan.simulation.warm_start import maximal_warm_start
    from mbplan.tasks.obstacle import joint_interpolation, robot_description
    from mbplan.transcription.manipulator import manipulator_problem

    jit = jit_available()
    mm = maximal_model(robot_description(task.robot))
    problem = manipulator_problem(mm, task_ocp(task, mm), jit)
    x0 = problem.check_point(maximal_warm_start(mm, joint_interpolation(task), task.dt, jit=jit))
    return problem, x0


def drone_task(index: int, n: int = 100, seed: int = 0, limits: bool = False):
    """Drone docking case ``index`` of ``n`` (RIPM paper §VIII.B)."""
    from mbplan.tasks.drone import sample_docking_cases

    return sample_docking_cases(n, seed, with_input_limits=limits)[index]


def drone_ripm_problem(task) -> tuple[Any, Any]:
    from mbplan.tasks.drone import geodesic_initial_guess
    from mbplan.transcription.quadrotor import quadrotor_problem

    problem = quadrotor_problem(task)
    return problem, problem.check_point(geodesic_initial_guess(task))


CHAIN_LINKS = (4, 8, 16, 32, 64)
CHAIN_LENGTH = 1.0  # m, whole chain
CHAIN_MASS = 2.0  # kg, whole chain


def chain_urdf(n: int) -> str:
    """URDF of a hanging serial chain of ``n`` equal links (revolute x, y, x, ...), 1 m, 2 kg."""
    L, m, r = CHAIN_LENGTH / n, CHAIN_MASS / n, 0.01
    ixx, izz = m * (3 * r * r + L * L) / 12, m * r * r / 2
    parts = ['<?xml version="1.0"?>', f'<robot name="chain{n}">', '<link name="base"/>']
    parent = "base"
    for i in range(n):
        link = f"link{i + 1}"
        parts.append(
            f'<link name="{link}"><inertial><origin xyz="0 0 {-L / 2}"/><mass value="{m}"/>'
            f'<inertia ixx="{ixx}" iyy="{ixx}" izz="{izz}" ixy="0" ixz="0" iyz="0"/>'
            "</inertial></link>"
        )
        axis = "1 0 0" if i % 2 == 0 else "0 1 0"
        z = -L if i else 0.0
        parts.append(
            f'<joint name="joint{i + 1}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{link}"/><origin xyz="0 0 {z}"/><axis xyz="{axis}"/>'
            '<limit lower="-3.1" upper="3.1" effort="100" velocity="10"/></joint>'
        )
        parent = link
    parts.append("</robot>")
    return "\n".join(parts)


@functools.cache
def _chain_path(n: int) -> str:
    path = Path(tempfile.gettempdir()) / f"mbplan-chain{n}.urdf"
    text = chain_urdf(n)
    if not path.exists() or path.read_text() != text:
        tmp = path.with_suffix(f".{time.time_ns()}.tmp")
        tmp.write_text(text)
        tmp.replace(path)
    return str(path)


def chain_task(n: int, N: int = 40):
    """Reach with an ``n``-link hanging chain: from rest at q = 0 to a curl of 1.2 rad total."""
    from mbplan.tasks.obstacle import ObstacleTask

    q_target = np.full(n, 1.2 / n)
    return ObstacleTask(
        robot=_chain_path(n), N=N, q0=np.zeros(n), q_target=q_target, obstacles=(),
        warm_start="linear",
    )  # fmt: skip


def _iiwa(i: int):
    return (*manipulator_ripm_problem(iiwa_task(i)), RIPMOptions(tol=1e-6, max_iter=500))


def _drone(i: int, limits: bool = False):
    return (*drone_ripm_problem(drone_task(i, limits=limits)), RIPMOptions(tol=1e-6, max_iter=100))


def _chain(n: int):
    return (*manipulator_ripm_problem(chain_task(n)), RIPMOptions(tol=1e-6, max_iter=500))


TASKS: dict[str, Callable[[int], tuple]] = {
    "iiwa-com": _iiwa,
    "drone": _drone,
    "drone-limits": functools.partial(_drone, limits=True),
    **{f"chain{n}": (lambda _i, n=n: _chain(n)) for n in CHAIN_LINKS},
}

# ------------------------------------------------------------------------------- profile


class _TimedProblem:
    """The problem with timers around ``evaluate``, ``values`` and ``retract``."""

    def __init__(self, problem: Any, clock: dict[str, float]) -> None:
        self._p, self._clock = problem, clock
        self.n, self.n_eq, self.n_ineq = problem.n, problem.n_eq, problem.n_ineq

    def _timed(self, key: str, fn: Callable, *args: Any, **kw: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return fn(*args, **kw)
        finally:
            self._clock[key] += time.perf_counter() - t0
            self._clock["n_" + key] += 1

    def evaluate(self, *args: Any, **kw: Any) -> Any:
        return self._timed("evaluate", self._p.evaluate, *args, **kw)

    def values(self, *args: Any, **kw: Any) -> Any:
        return self._timed("values", self._p.values, *args, **kw)

    def retract(self, *args: Any, **kw: Any) -> Any:
        return self._timed("retract", self._p.retract, *args, **kw)


PROFILE_KEYS = ("evaluate", "values", "retract", "assembly", "factorize", "solve")


@contextmanager
def _timed_kkt(clock: dict[str, float]):
    """Timers on the KKT system's methods (class-level patch, restored on exit)."""
    cls = ls.KKTSystem
    saved = {name: getattr(cls, name) for name in ("set_matrices", "factorize", "solve")}
    key = {"set_matrices": "assembly", "factorize": "factorize", "solve": "solve"}

    def wrap(name: str) -> Callable:
        fn = saved[name]

        def timed(self: Any, *args: Any, **kw: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return fn(self, *args, **kw)
            finally:
                clock[key[name]] += time.perf_counter() - t0
                clock["n_" + key[name]] += 1

        return timed

    try:
        for name in saved:
            setattr(cls, name, wrap(name))
        yield
    finally:
        for name, fn in saved.items():
            setattr(cls, name, fn)


def profile_solve(problem: Any, x0: Any, options: RIPMOptions) -> dict[str, Any]:
    """Solve once (after a warm-up solve for compilation and pattern analysis) and return the
    time per iteration of each part, in ms, with counts per iteration."""
    solve_ripm(problem, x0, options)
    clock: dict[str, float] = dict.fromkeys(PROFILE_KEYS, 0.0)
    clock |= {"n_" + k: 0 for k in PROFILE_KEYS}
    with _timed_kkt(clock):
        t0 = time.perf_counter()
        res: RIPMResult = solve_ripm(_TimedProblem(problem, clock), x0, options)
        wall = time.perf_counter() - t0
    it = max(res.iterations, 1)
    parts = sum(clock[k] for k in PROFILE_KEYS)
    row: dict[str, Any] = {
        "status": res.status.name,
        "iterations": res.iterations,
        "restoration_iterations": int(np.sum(res.history.restoration)),
        "total_ms": 1e3 * wall,
        "per_iter_ms": 1e3 * wall / it,
    }
    for k in PROFILE_KEYS:
        row[k + "_ms"] = 1e3 * clock[k] / it
    row["python_ms"] = 1e3 * (wall - parts) / it
    for k in PROFILE_KEYS:
        row[k + "_per_iter"] = clock["n_" + k] / it
    row["kkt_dim"] = problem.n + problem.n_eq + problem.n_ineq
    return row
