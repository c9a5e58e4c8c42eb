"""Robustness: the RIPM (maximal coordinates) against IPOPT (generalized coordinates) on the
seeded families of :mod:`mbplan.tasks.robustness`, chosen for what makes trajectory optimization
hard (graded torque limits on long chains, mesh-collision arms among boxes, goals near joint
limits, at rest or near singular configurations, the paper tasks from the linear warm start).
The table that matters is the failure table: every case a method did not solve and verify,
with its status and the verifier's reasons, and whether the baseline solved it.

Regenerate: ``mbplan bench robustness --n 20 --seed 0 --out benchmarks/results/robustness``.
"""

from __future__ import annotations

from mbplan.benchmarks.families import Family, Suite
from mbplan.tasks import robustness as tasks

FAMILIES = {
    f.name: f
    for f in (
        Family(
            "graded_chain",
            tasks.graded_chain_case,
            "linear",
            "A hanging chain of 8, 16, 32 or 64 links (cycling; 4.8 m, 16 kg) with torque "
            "limits falling from 65 to 6 N m along it and 4 rad/s, reaching a random wave in 2 s "
            "(N = 40; the paper's tracking costs and a hard terminal goal).",
        ),
        Family(
            "arm_boxes",
            tasks.arm_boxes_case,
            "via",
            "Mesh-collision arms (panda, ur5, ur10, kinova, xarm7, so100, cycling) move the tool "
            "to a random pose among 1–3 random boxes, 2 cm clearance (N = 40, 3 s).",
        ),
        Family(
            "near_limits",
            tasks.near_limits_case,
            "linear",
            "Arms (iiwa, panda, ur5, ur10, kinova, xarm7, z1, so100, cycling) reach a joint "
            "goal with half its joints within 2 % of a position limit (N = 40, 3 s).",
        ),
        Family(
            "rest_goal",
            tasks.rest_goal_case,
            "linear",
            "The same arms reach a random tool pose and stop there (terminal velocity zero).",
        ),
        Family(
            "near_singular",
            tasks.near_singular_case,
            "linear",
            "The same arms reach the tool pose of the most singular of 200 sampled configurations.",
        ),
        Family(
            "paper_linear",
            tasks.paper_linear_case,
            "linear",
            "The paper's iiwa-obstacle (even cases) and drone-docking (odd cases) tasks from the "
            "linear warm start.",
        ),
    )
}

SUITE = Suite(
    name="robustness",
    title="Robustness: RIPM (maximal) vs IPOPT (generalized) on hard task families",
    families=FAMILIES,
    intro="Families of `mbplan.tasks.robustness`, {n} cases each, case i drawn from "
    "`numpy.random.default_rng((seed, i, family))` with seed {seed}. *ipopt only*: cases IPOPT "
    "solved and verified that another method did not.",
    n=20,
)
