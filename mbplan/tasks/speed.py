"""The speed benchmark's tasks: iiwa, drone and chain-reach problems as the RIPM sees them, one
small function per task, and the chain reach as a benchmark job."""

from __future__ import annotations

import functools
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mbplan.planning.methods import LGVI_RIPM_OPTIONS
from mbplan.solvers import RIPMOptions
from mbplan.workspace import Workspace


def iiwa_task(index: int, n: int = 100, seed: int = 0, constraint: str = "com"):
    """iiwa obstacle case ``index`` of ``n`` (N = 40) as an OCP (:mod:`mbplan.tasks.paper`)."""
    from mbplan.tasks.paper import iiwa_obstacle, iiwa_obstacle_starts

    q0 = iiwa_obstacle_starts(n, seed, constraint)[index]
    return iiwa_obstacle(q0, N=40, constraint=constraint)


def maximal_ripm_problem(
    ocp, warm_start: str = "via", workspace: Workspace | None = None
) -> tuple[Any, Any]:
    """The RIPM's problem and warm start for an OCP, as ``plan(ocp, "ripm")`` builds them (the
    free-body formulation for a :class:`~mbplan.robots.free_body.FreeBody`; its structures kept
    in ``workspace``)."""
    from mbplan.engine.jit import jit_available
    from mbplan.planning.initial_guess import initial_path
    from mbplan.planning.methods import maximal_start

    nlp, x0 = maximal_start(ocp, initial_path(ocp, warm_start), jit_available(), workspace)
    return nlp.problem, x0


def drone_task(index: int, n: int = 100, seed: int = 0, limits: bool = False):
    """Drone docking case ``index`` of ``n`` (RIPM paper §VIII.B) as an OCP."""
    from mbplan.tasks.drone import sample_docking_cases
    from mbplan.tasks.paper import drone_docking

    return drone_docking(sample_docking_cases(n, seed, with_input_limits=limits)[index])


CHAIN_LINKS = (4, 8, 16, 32, 64)
CHAIN_LENGTH = 1.0  # m, whole chain
CHAIN_MASS = 2.0  # kg, whole chain


def chain_urdf(
    n: int,
    length: float = CHAIN_LENGTH,
    mass: float = CHAIN_MASS,
    efforts: tuple[float, float] = (100.0, 100.0),
    velocity: float = 10.0,
    position_range: float = 3.1,
    name: str = "chain",
) -> str:
    """URDF of a hanging serial chain of ``n`` equal links (revolute x, y, x, ...) of total
    ``length`` and ``mass``, position limits ``±position_range``, torque limits falling linearly
    from ``efforts[0]`` at the first joint to ``efforts[1]`` at the last."""
    L, m, r = length / n, mass / n, 0.01
    ixx, izz = m * (3 * r * r + L * L) / 12, m * r * r / 2
    effort = np.linspace(*efforts, n)
    parts = ['<?xml version="1.0"?>', f'<robot name="{name}{n}">', '<link name="base"/>']
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
            f'<limit lower="{-position_range}" upper="{position_range}" '
            f'effort="{np.format_float_positional(effort[i], 4, trim="-")}" '
            f'velocity="{velocity:g}"/></joint>'
        )
        parent = link
    parts.append("</robot>")
    return "\n".join(parts)


# process-wide cache, result-neutral: the URDF text is a function of n alone
@functools.cache
def _chain_path(n: int) -> str:
    path = Path(tempfile.gettempdir()) / f"mbplan-chain{n}.urdf"
    text = chain_urdf(n)
    if not path.exists() or path.read_text() != text:
        tmp = path.with_suffix(f".{time.time_ns()}.tmp")
        tmp.write_text(text)
        tmp.replace(path)
    return str(path)


CHAIN_CURL = 1.2  # rad, the reach's total curl (every joint 1.2 / n)
CHAIN_BEND = 1.2  # rad: the obstacle task: the x joints share it at the start, the y at the goal
CHAIN_CYLINDER = ((-0.25, 0.3), 0.05)  # vertical cylinder: centre xy, radius (m)
CHAIN_MARGIN = 0.08  # m, eq. (62) margin of the link COMs (the replay deviates ~3 cm between knots)
CHAIN_VELOCITY = 2.0  # rad/s, joint speed limit of the obstacle task (no whipping past it)


def _bend(n: int, about_x: bool) -> np.ndarray:
    """The x (``about_x``) or the y joints share :data:`CHAIN_BEND`, the others stay at 0."""
    rows = (np.arange(n) % 2 == 0) == about_x
    return np.where(rows, CHAIN_BEND / max(int(rows.sum()), 1), 0.0)


def chain_start(n: int, obstacle: bool = False) -> np.ndarray:
    """The reach's start at rest: hanging (q = 0), or (``obstacle``) the x joints' bend, the
    chain curled in the y-z plane towards +y."""
    return _bend(n, about_x=True) if obstacle else np.zeros(n)


def chain_target(n: int, obstacle: bool = False) -> np.ndarray:
    """The reach's goal: a uniform curl of :data:`CHAIN_CURL`, or (``obstacle``) the y joints'
    bend, the chain curled in the x-z plane towards -x. The obstacle task's start and goal are
    planar curls, stable equilibria under their holding torques at every size (a bend that
    curls the chain out of one vertical plane is open-loop unstable, with a growth rate of
    ~n^1.5 / s); the linear interpolation between them sweeps the link COMs through
    :data:`CHAIN_CYLINDER` (≥ 11 cm into it with the margin for 4…64 links) while start and goal
    keep ≥ 11 cm clear of it and its margin."""
    return _bend(n, about_x=False) if obstacle else np.full(n, CHAIN_CURL / n)


def chain_task(n: int, N: int = 40, obstacle: bool = False):
    """Reach with an ``n``-link chain from rest at :func:`chain_start` to :func:`chain_target`;
    ``obstacle``: around a vertical cylinder, every link COM outside it (eq. 62), joint speeds
    within :data:`CHAIN_VELOCITY`."""
    from mbplan.ocp.scene import Scene
    from mbplan.tasks.paper import add_obstacle_constraint, tracking_ocp

    scene = None
    if obstacle:
        (x, y), r = CHAIN_CYLINDER
        scene = Scene().add_cylinder("cylinder", r, 1.2, (x, y, -0.6))
    vmax = np.full(n, CHAIN_VELOCITY) if obstacle else None
    start, target = chain_start(n, obstacle), chain_target(n, obstacle)
    ocp = tracking_ocp(_chain_path(n), start, target, scene, N=N, velocity_limit=vmax)
    return add_obstacle_constraint(ocp, "com", CHAIN_MARGIN) if obstacle else ocp


def _iiwa(i: int, constraint: str = "com"):
    return (
        *maximal_ripm_problem(iiwa_task(i, constraint=constraint)),
        RIPMOptions(tol=1e-6, max_iter=500, **LGVI_RIPM_OPTIONS),
    )


def _drone(i: int, limits: bool = False):
    return (
        *maximal_ripm_problem(drone_task(i, limits=limits)),
        RIPMOptions(tol=1e-6, max_iter=100, **LGVI_RIPM_OPTIONS),
    )


def chain_problem(n: int, obstacle: bool = False):
    """The RIPM problem, warm start and options of the ``n``-link chain reach."""
    return (
        *maximal_ripm_problem(chain_task(n, obstacle=obstacle), "linear"),
        RIPMOptions(tol=1e-6, max_iter=500, **LGVI_RIPM_OPTIONS),
    )


TASKS: dict[str, Callable[[int], tuple]] = {
    "iiwa-com": _iiwa,
    "iiwa-distance": functools.partial(_iiwa, constraint="distance"),
    "drone": _drone,
    "drone-limits": functools.partial(_drone, limits=True),
    **{f"chain{n}": (lambda _i, n=n: chain_problem(n)) for n in CHAIN_LINKS},
    **{f"chain{n}-obstacle": (lambda _i, n=n: chain_problem(n, True)) for n in CHAIN_LINKS},
}
