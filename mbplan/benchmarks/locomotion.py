"""Gaits with hard contacts: the RIPM (maximal coordinates: contacts as joints to the world
during their stances) against IPOPT (generalized coordinates: contact forces as variables of
eq. (61)).

Per family of :mod:`mbplan.tasks.locomotion` (solo12 and ANYmal walking, trotting, pacing,
bounding, jumping on Crocoddyl's schedules; talos_legs walking on flat soles): the nominal step
and seeded step lengths and heights, every method from the same linear warm start. A
:class:`~mbplan.benchmarks.families.Suite` run by :func:`mbplan.benchmarks.families.run`.

Regenerate: ``mbplan bench locomotion --n 20 --seed 0 --methods ripm,ipopt --out benchmarks/results/locomotion``.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import Any

from mbplan.benchmarks.families import Family, Suite
from mbplan.tasks.locomotion import FAMILIES, HEIGHT_RANGE, LENGTH_RANGE, WARM_START, gait_case


def crocoddyl_anchor(families: Sequence[str], seed: int) -> dict[str, Any]:
    """Crocoddyl's FDDP on its own problem of each family's nominal step
    (:mod:`mbplan.baselines.crocoddyl_gaits`; ``seed``: unused, the nominal step is not drawn),
    or why it did not run."""
    try:
        from mbplan.baselines.crocoddyl_gaits import fddp_gait
    except ImportError as err:  # the baselines extra is not installed
        return {"unavailable": str(err)}
    out = {}
    for name in families:
        f = FAMILIES[name]
        args = (f.length, f.height, f.dt, f.step_knots, f.support_knots)
        out[name] = fddp_gait(f.robot, f.feet, f.gait, *args)
    return out


def anchor_markdown(profile: dict[str, Any]) -> list[str]:
    """The anchor's section of results.md."""
    lines = [
        "## Crocoddyl FDDP on its own problem (timing anchor)",
        "",
        "The nominal step of each family as Crocoddyl's `SimpleQuadrupedalGaitProblem` or "
        "`SimpleBipedGaitProblem` (contact dynamics, impulse models, friction and wrench cones "
        "as penalties, its own weights, no joint limits) solved by its FDDP from its own start: "
        "solve time, not verified by `mbplan.verify` (`mbplan.baselines.crocoddyl_gaits`); "
        "*cone*: the largest violation of the hard cones (friction cone, mu = 0.7; a sole's "
        "contact wrench cone of Crocoddyl's 0.1 m × 0.05 m box) by its contact forces, which "
        "its penalty lets them leave (N; N m on a sole's torque rows). Compare with case 0's "
        "rows above.",
        "",
    ]
    if "unavailable" in profile:
        return [*lines, f"Not run: {profile['unavailable']}"]
    lines += [
        "| family | knots | iterations | converged | solve [s] | cone |",
        "|---|---:|---:|---|---:|---:|",
    ]
    for name, r in profile.items():
        lines.append(
            f"| {name} | {r['knots']} | {r['iterations']} | {r['converged']} | "
            f"{r['solve_time_s']:.3f} | {r['max_cone_violation']:.3g} |"
        )
    return lines


SUITE = Suite(
    name="locomotion",
    title="Gaits with hard contacts: RIPM (maximal) vs IPOPT (generalized)",
    families={
        name: Family(name, partial(gait_case, name), WARM_START, f.describe())
        for name, f in FAMILIES.items()
    },
    intro="Per family, a robot on Crocoddyl's schedule (`mbplan.locomotion.quadruped_gait`, "
    "`biped_gait`); case 0 the nominal step, the others a step length of "
    f"{LENGTH_RANGE} × and a height of {HEIGHT_RANGE} × the nominal one "
    "(`mbplan.tasks.locomotion`, seed {seed}). Contact forces (wrenches) as variables inside "
    "hard friction pyramids (contact wrench cones), swing feet above the ground, Crocoddyl's "
    "centre-of-mass and swing-foot targets as costs.",
    n=20,
    family_flag="gaits",
    family_noun="gait",
    profile=crocoddyl_anchor,
    profile_markdown=anchor_markdown,
)
