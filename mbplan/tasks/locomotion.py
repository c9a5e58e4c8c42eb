"""Quadruped gaits (``mbplan bench locomotion``): solo12 on Crocoddyl's walk, trot, pace, bound
and jump schedules (:func:`mbplan.locomotion.quadruped_gait`) at Δt = 20 ms, steps of
:data:`STEP_KNOTS` intervals and supports of :data:`SUPPORT_KNOTS`. Case 0 of a gait is its
nominal step (:data:`STEP_LENGTH`, :data:`STEP_HEIGHT`); case ``i ≥ 1`` draws the step length
and height from ``numpy.random.default_rng((seed, i, GAIT_TAG[gait]))``."""

from __future__ import annotations

import numpy as np

from mbplan.errors import InputError
from mbplan.locomotion import QUADRUPED_GAITS, quadruped_gait
from mbplan.ocp.problem import OCP

ROBOT = "solo12"
FEET = ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")
GAITS = tuple(QUADRUPED_GAITS)
GAIT_TAG = {name: i for i, name in enumerate(GAITS)}
DT, STEP_KNOTS, SUPPORT_KNOTS = 0.02, 8, 2
STEP_LENGTH, STEP_HEIGHT = 0.1, 0.05  # m
LENGTHS, HEIGHTS = (0.05, 0.15), (0.03, 0.07)  # m: the drawn cases' ranges
WARM_START = "linear"


def gait_case(gait: str, index: int, seed: int = 0) -> OCP:
    """Case ``index`` of ``gait`` (module docstring)."""
    if gait not in GAIT_TAG:
        raise InputError(f"unknown gait {gait!r}; choose from {', '.join(GAITS)}")
    length, height = STEP_LENGTH, STEP_HEIGHT
    if index > 0:
        rng = np.random.default_rng((seed, index, GAIT_TAG[gait]))
        length, height = rng.uniform(*LENGTHS), rng.uniform(*HEIGHTS)
    return quadruped_gait(
        ROBOT, FEET, gait=gait, step_length=float(length), step_height=float(height), dt=DT,
        step_knots=STEP_KNOTS, support_knots=SUPPORT_KNOTS,
    )  # fmt: skip
