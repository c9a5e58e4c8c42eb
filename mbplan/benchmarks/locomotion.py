"""Quadruped gaits with hard contacts: the RIPM (maximal coordinates: contacts as ball joints to
the world during their stances) against IPOPT (generalized coordinates: contact forces as
variables of eq. (61)).

Per gait of :mod:`mbplan.tasks.locomotion` (solo12 walking, trotting, pacing, bounding,
jumping on Crocoddyl's schedules): the nominal step and seeded step lengths and heights, every
method from the same linear warm start. A :class:`~mbplan.benchmarks.families.Suite` run by
:func:`mbplan.benchmarks.families.run`.

Regenerate: ``mbplan bench locomotion --n 20 --seed 0 --methods ripm,ipopt --out benchmarks/results/locomotion``.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import Any

from mbplan.benchmarks.families import Family, Suite
from mbplan.tasks.locomotion import (
    DT,
    FEET,
    GAITS,
    HEIGHTS,
    LENGTHS,
    ROBOT,
    STEP_HEIGHT,
    STEP_KNOTS,
    STEP_LENGTH,
    SUPPORT_KNOTS,
    WARM_START,
    gait_case,
)


def crocoddyl_anchor(gaits: Sequence[str], seed: int) -> dict[str, Any]:
    """Crocoddyl's FDDP on its own problem of each gait's nominal step
    (:mod:`mbplan.baselines.crocoddyl_gaits`; ``seed``: unused, the nominal step is not drawn),
    or why it did not run."""
    try:
        from mbplan.baselines.crocoddyl_gaits import fddp_gait
    except ImportError as err:  # the baselines extra is not installed
        return {"unavailable": str(err)}
    args = (STEP_LENGTH, STEP_HEIGHT, DT, STEP_KNOTS, SUPPORT_KNOTS)
    return {g: fddp_gait(ROBOT, FEET, g, *args) for g in gaits}


def anchor_markdown(profile: dict[str, Any]) -> list[str]:
    """The anchor's section of results.md."""
    lines = [
        "## Crocoddyl FDDP on its own problem (timing anchor)",
        "",
        "The nominal step of each gait as Crocoddyl's `SimpleQuadrupedalGaitProblem` (contact "
        "dynamics, impulse models, friction cones as penalties, its own weights) solved by its "
        "FDDP from its own start: solve time, not verified by `mbplan.verify` "
        "(`mbplan.baselines.crocoddyl_gaits`). Compare with case 0's rows above.",
        "",
    ]
    if "unavailable" in profile:
        return [*lines, f"Not run: {profile['unavailable']}"]
    lines += ["| gait | knots | iterations | converged | solve [s] |", "|---|---:|---:|---|---:|"]
    for gait, r in profile.items():
        lines.append(
            f"| {gait} | {r['knots']} | {r['iterations']} | {r['converged']} | "
            f"{r['solve_time_s']:.3f} |"
        )
    return lines


SUITE = Suite(
    name="locomotion",
    title="Quadruped gaits with hard contacts: RIPM (maximal) vs IPOPT (generalized)",
    families={
        g: Family(
            g,
            partial(gait_case, g),
            WARM_START,
            f"solo12 {g}s on Crocoddyl's {g} schedule, hard friction cones (mu = 0.7).",
        )
        for g in GAITS
    },
    intro="Per gait, solo12 on Crocoddyl's schedule (`mbplan.locomotion.quadruped_gait`): "
    f"Δt = {DT:g} s, steps of {STEP_KNOTS} intervals, supports of {SUPPORT_KNOTS}; case 0 the "
    f"nominal step (0.1 m long, 0.05 m high), the others a step length in {LENGTHS} m and a "
    f"height in {HEIGHTS} m (`mbplan.tasks.locomotion`, seed {{seed}}). Point contacts with "
    "their forces as variables inside hard friction pyramids, swing feet above the ground, "
    "Crocoddyl's centre-of-mass and swing-foot targets as costs; no joint limits.",
    n=20,
    family_flag="gaits",
    family_noun="gait",
    profile=crocoddyl_anchor,
    profile_markdown=anchor_markdown,
)
