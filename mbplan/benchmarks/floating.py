"""Floating-base robots in free flight: the RIPM (maximal coordinates: the base a free body)
against IPOPT (generalized coordinates: Pinocchio's free flyer, its quaternion in R⁴).

Per robot of :mod:`mbplan.tasks.floating` (``solo12``, ``anymal``, ``go2``, ``talos_legs``):
seeded random joint targets reached in free flight, every method from the same linear warm
start. A :class:`~mbplan.benchmarks.families.Suite` run by
:func:`mbplan.benchmarks.families.run`.

Regenerate: ``mbplan bench floating --n 10 --seed 0 --out benchmarks/results/floating``.
"""

from __future__ import annotations

from functools import partial

from mbplan.benchmarks.families import Family, Suite
from mbplan.tasks.floating import DURATION, FLOATING_ROBOTS, WARM_START, N, free_flight_case

SUITE = Suite(
    name="floating",
    title="Floating bases in free flight: RIPM (maximal) vs IPOPT (generalized)",
    families={
        r: Family(
            r,
            partial(free_flight_case, r),
            WARM_START,
            f"{r} released at rest 1 m up turns every joint by a random angle.",
        )
        for r in FLOATING_ROBOTS
    },
    intro="Per robot, released at rest 1 m above the ground (no contacts), every joint turned "
    "by up to 0.8 rad from the standing posture (within the central half of its range) at the "
    "last knot (a hard constraint), the "
    f"least torque, within the joint limits; N = {N} steps, {DURATION:g} s "
    "(`mbplan.tasks.floating`, seed {seed}).",
    n=10,
    family_flag="robots",
    family_noun="robot",
)
