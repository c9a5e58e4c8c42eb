"""Gaits (``mbplan bench locomotion``): solo12 and ANYmal on Crocoddyl's walk, trot, pace, bound
and jump schedules (:func:`mbplan.locomotion.quadruped_gait`), talos_legs on its walk
(:func:`mbplan.locomotion.biped_gait`), each a family :data:`FAMILIES` ``"<robot>-<gait>"`` of
:class:`GaitFamily` parameters. Case 0 of a family is its nominal step (``length``,
``height``); case ``i ≥ 1`` draws the step length from ``(0.5, 1.5) × length`` and the height
from ``(0.6, 1.4) × height`` with ``numpy.random.default_rng((seed, i, tag))``, ``tag`` the
family's index in :data:`FAMILIES`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbplan.errors import InputError
from mbplan.locomotion import QUADRUPED_GAITS, biped_gait, quadruped_gait
from mbplan.ocp.problem import OCP

LENGTH_RANGE, HEIGHT_RANGE = (0.5, 1.5), (0.6, 1.4)  # the drawn cases' factors
WARM_START = "linear"


@dataclass(frozen=True)
class GaitFamily:
    """A robot's gait at Δt ``dt`` with steps of ``step_knots`` intervals and supports of
    ``support_knots``, nominal step ``length`` × ``height`` (m); ``limits``: the robot's joint
    limits as hard constraints (:data:`mbplan.locomotion.gaits.LIMITS`)."""

    robot: str
    gait: str
    feet: tuple[str, ...]
    length: float
    height: float
    dt: float = 0.02
    step_knots: int = 8
    support_knots: int = 2
    limits: tuple[str, ...] = ()

    @property
    def biped(self) -> bool:
        return len(self.feet) == 2

    def describe(self) -> str:
        """One line for results.md."""
        contacts = "flat soles (6-D, contact wrench cones)" if self.biped else "point feet"
        limits = f", its joint {' and '.join(self.limits)} limits" if self.limits else ""
        return (
            f"{self.robot} {self.gait}: Δt = {self.dt:g} s, steps of {self.step_knots} "
            f"intervals, supports of {self.support_knots}, nominal step {self.length:g} m long "
            f"and {self.height:g} m high; {contacts}, mu = 0.7{limits}."
        )


SOLO12 = ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")
ANYMAL = ("LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT")
TALOS = ("left_sole_link", "right_sole_link")
_ANYMAL_STEP = {"walk": (0.25, 0.15), "jump": (0.3, 0.15)}  # Crocoddyl's example; others 0.15, 0.1
FAMILIES: dict[str, GaitFamily] = {
    **{f"solo12-{g}": GaitFamily("solo12", g, SOLO12, 0.1, 0.05) for g in QUADRUPED_GAITS},
    **{
        f"anymal-{g}": GaitFamily(
            "anymal", g, ANYMAL, *_ANYMAL_STEP.get(g, (0.15, 0.1)), limits=("velocity",)
        )
        for g in QUADRUPED_GAITS
    },
    "talos_legs-walk": GaitFamily(
        "talos_legs", "walk", TALOS, 0.3, 0.05, dt=0.03, step_knots=10, limits=("velocity",)
    ),
}
"""Every family of the benchmark, by name."""


def gait_case(family: str, index: int, seed: int = 0) -> OCP:
    """Case ``index`` of ``family`` (module docstring)."""
    if family not in FAMILIES:
        raise InputError(f"unknown gait family {family!r}; choose from {', '.join(FAMILIES)}")
    f = FAMILIES[family]
    length, height = f.length, f.height
    if index > 0:
        rng = np.random.default_rng((seed, index, list(FAMILIES).index(family)))
        length *= rng.uniform(*LENGTH_RANGE)
        height *= rng.uniform(*HEIGHT_RANGE)
    build = biped_gait if f.biped else quadruped_gait
    return build(
        f.robot, f.feet, gait=f.gait, step_length=float(length), step_height=float(height),
        dt=f.dt, step_knots=f.step_knots, support_knots=f.support_knots, limits=f.limits,
    )  # fmt: skip
