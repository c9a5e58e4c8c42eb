"""Scenes: the RIPM (maximal) against IPOPT (generalized) on real robots among obstacles with
coal distances (:mod:`mbplan.tasks.scenes`) — the UR5 over a shelf and the panda between boxes
(the example task files, repeated for their timing), the iiwa with coal distances and a sweep of
mesh-collision arms to random poses among random boxes — solved & verified (the verifier's
replay keeps 90 % of every margin between the knots), times, the least margin kept, and the
RIPM's time per iteration split into coal distances, linear algebra and the rest.

Regenerate: ``mbplan bench scenes --n 100 --seed 0 --out benchmarks/results/scenes``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from mbplan.benchmarks.families import Family, Suite
from mbplan.benchmarks.kkt_profile import profile_solve
from mbplan.benchmarks.speed_report import fmt
from mbplan.errors import InputError
from mbplan.ocp.problem import OCP
from mbplan.planning.methods import LGVI_RIPM_OPTIONS
from mbplan.solvers import RIPMOptions
from mbplan.tasks import scenes
from mbplan.tasks.speed import maximal_ripm_problem

EXAMPLE_TASKS = Path(__file__).resolve().parents[2] / "examples" / "tasks"


def example_task(name: str) -> OCP:
    """The OCP of ``examples/tasks/NAME.toml``."""
    from mbplan.taskfile import load_task

    path = EXAMPLE_TASKS / f"{name}.toml"
    if not path.is_file():
        raise InputError(f"{path}: no such example task (the scenes read a source checkout)")
    return load_task(path).ocp


def ur5_shelf_case(index: int, seed: int = 0) -> OCP:
    """``examples/tasks/ur5_shelf.toml`` (every case: the published task)."""
    return example_task("ur5_shelf")


def panda_boxes_case(index: int, seed: int = 0) -> OCP:
    """``examples/tasks/panda_boxes.toml`` (every case: the published task)."""
    return example_task("panda_boxes")


FAMILIES = {
    f.name: f
    for f in (
        Family(
            "ur5_shelf",
            ur5_shelf_case,
            "via",
            "`examples/tasks/ur5_shelf.toml`: the UR5 (collision meshes as convex hulls) moves "
            "its tool over a shelf of three boxes, 2 cm margin kept between the knots (N = 40); "
            "every case the same task.",
            n=5,
        ),
        Family(
            "panda_boxes",
            panda_boxes_case,
            "via",
            "`examples/tasks/panda_boxes.toml`: the panda (meshes as hulls, fingers free) puts "
            "its hand down between two boxes, 2 cm margin between the knots (N = 30); every "
            "case the same task.",
            n=5,
        ),
        Family(
            "iiwa_distance",
            scenes.iiwa_distance_case,
            "via",
            "The speed benchmark's iiwa reach around a sphere with coal distances of its "
            "primitive collision shapes (N = 40), random starts.",
            n=20,
        ),
        Family(
            "mesh_sweep",
            scenes.mesh_sweep_case,
            "via",
            "Mesh-collision arms (panda, ur5, ur10, kinova, xarm7, so100, cycling) move the tool "
            "to a random pose among 1–3 random boxes, 2 cm margin between the knots (N = 40, "
            "3 s): the robustness benchmark's `arm_boxes` cases, with the margin between the "
            "knots too.",
        ),
    )
}


def profile(families: Sequence[str], seed: int) -> dict[str, Any]:
    """The RIPM's per-iteration profile (:func:`~mbplan.benchmarks.kkt_profile.profile_solve`)
    of case 0 of each family."""
    options = RIPMOptions(tol=1e-6, max_iter=500, **LGVI_RIPM_OPTIONS)
    entries = {}
    for name in families:
        family = FAMILIES[name]
        problem, x0 = maximal_ripm_problem(family.case(0, seed), family.warm_start)
        entries[name] = profile_solve(problem, x0, options)
    return entries


def profile_markdown(entries: dict[str, Any]) -> list[str]:
    """The profile's section of results.md."""
    lines = [
        "## Inside a RIPM iteration",
        "",
        "Case 0 of each family solved again after a warm-up solve, per iteration: *distances* "
        "is the coal distance rows' evaluation (the compiled coal pass and the derivatives "
        "around it), *linear algebra* the KKT system's assembly, factorization and solves, "
        "*rest* everything else (the other rows' evaluation, retraction, line search); *pairs* "
        "the (geometry, obstacle) pairs sent to coal per iteration, *µs/pair* the compiled "
        "pass's time per pair.",
        "",
        "| family | status | iterations | per iteration [ms] | distances [ms] (share) "
        "| linear algebra [ms] | rest [ms] | pairs | µs/pair |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, e in entries.items():
        algebra = e["assembly_ms"] + e["factorize_ms"] + e["solve_ms"]
        distances = e.get("distances_ms", 0.0)
        rest = e["per_iter_ms"] - algebra - distances
        lines.append(
            f"| {name} | {e['status']} | {e['iterations']} | {e['per_iter_ms']:.2f} "
            f"| {distances:.2f} ({100 * e.get('distance_share', 0.0):.0f} %) | {algebra:.2f} "
            f"| {rest:.2f} | {fmt(e.get('coal_pairs_per_iter'), digits=0)} "
            f"| {fmt(e.get('us_per_coal_pair'), digits=2)} |"
        )
    return lines


SUITE = Suite(
    name="scenes",
    title="Scenes: RIPM (maximal) vs IPOPT (generalized) among obstacles with coal distances",
    families=FAMILIES,
    intro="Families of `mbplan.benchmarks.scenes`: the example tasks 5 times each, the iiwa's first "
    "20 cases and {n} sweep cases, case i of the sweep drawn from "
    "`numpy.random.default_rng((seed, i, 'arm_boxes'))` with seed {seed}. *margin kept*: the "
    "smallest fraction of a margin the verifier's replay keeps between the knots (median over "
    "the converged runs; the verifier fails a plan below 90 %). *ipopt only*: cases IPOPT "
    "solved and verified that another method did not.",
    n=100,
    extra_columns=("margin_kept",),
    profile=profile,
    profile_markdown=profile_markdown,
)
