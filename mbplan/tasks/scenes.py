"""The scenes benchmark's tasks: real robots among obstacles with coal distances — the example
task files (UR5 over a shelf, panda between boxes; read from a source checkout's
``examples/tasks``), the speed benchmark's iiwa with coal distances and the mesh-collision arms
among random boxes of :mod:`mbplan.tasks.robustness`."""

from __future__ import annotations

from pathlib import Path

from mbplan.errors import InputError
from mbplan.ocp.problem import OCP

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


def iiwa_distance_case(index: int, seed: int = 0) -> OCP:
    """Case ``index`` of the speed benchmark's iiwa obstacle reach with coal distances."""
    from mbplan.tasks.speed import iiwa_task

    return iiwa_task(index, seed=seed, constraint="distance")


def mesh_sweep_case(index: int, seed: int = 0) -> OCP:
    """Case ``index`` of the robustness benchmark's ``arm_boxes`` with the margin kept between
    the knots too (the :class:`~mbplan.residuals.Distance` default)."""
    from mbplan.tasks.robustness import arm_boxes_case

    return arm_boxes_case(index, seed, between_knots=True)
