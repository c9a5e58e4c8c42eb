"""The scenes benchmark's generated tasks: the speed benchmark's iiwa with coal distances and
the mesh-collision arms among random boxes of :mod:`mbplan.tasks.robustness` with the margin
kept between the knots (the example task files it also plans are read by
:mod:`mbplan.benchmarks.scenes`)."""

from __future__ import annotations

from mbplan.ocp.problem import OCP


def iiwa_distance_case(index: int, seed: int = 0) -> OCP:
    """Case ``index`` of the speed benchmark's iiwa obstacle reach with coal distances."""
    from mbplan.tasks.speed import iiwa_task

    return iiwa_task(index, seed=seed, constraint="distance")


def mesh_sweep_case(index: int, seed: int = 0) -> OCP:
    """Case ``index`` of the robustness benchmark's ``arm_boxes`` with the margin kept between
    the knots too (the :class:`~mbplan.residuals.Distance` default)."""
    from mbplan.tasks.robustness import arm_boxes_case

    return arm_boxes_case(index, seed, between_knots=True)
