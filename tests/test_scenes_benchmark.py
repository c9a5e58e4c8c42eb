"""The scenes benchmark (:mod:`mbplan.benchmarks.scenes`): its tasks, its command line, the
per-family case counts and the RIPM profile with the coal distances' share."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mbplan.benchmarks import families, scenes
from mbplan.benchmarks.kkt_profile import profile_solve
from mbplan.cli.main import build_parser, main
from mbplan.errors import InputError
from mbplan.planning.methods import LGVI_RIPM_OPTIONS
from mbplan.solvers import RIPMOptions
from mbplan.tasks import robustness
from mbplan.tasks import scenes as tasks
from mbplan.tasks.speed import maximal_ripm_problem


def _clearance(ocp):
    return next(i for i in ocp.constraints if i.name == "clearance").residual


def test_the_scenes_are_the_example_tasks_the_iiwa_and_the_sweep_between_knots():
    shelf, panda = scenes.ur5_shelf_case(3), scenes.panda_boxes_case(0)
    assert (shelf.robot.name, len(shelf.scene), panda.robot.name) == ("ur5", 3, "panda")
    assert shelf.to_dict() == scenes.ur5_shelf_case(0, seed=7).to_dict()  # the published task
    sweep, knots_only = tasks.mesh_sweep_case(4), robustness.arm_boxes_case(4)
    assert _clearance(sweep).between_knots and not _clearance(knots_only).between_knots
    assert sweep.scene.names == knots_only.scene.names
    np.testing.assert_array_equal(sweep.q0, knots_only.q0)
    assert tasks.iiwa_distance_case(2).robot.name == "iiwa"


def test_a_missing_example_task_is_named(monkeypatch, tmp_path):
    monkeypatch.setattr(scenes, "EXAMPLE_TASKS", tmp_path)
    with pytest.raises(InputError, match=r"ur5_shelf\.toml: no such example task"):
        scenes.ur5_shelf_case(0)


def test_families_with_a_fixed_count_run_at_most_that_many_cases():
    shelf, sweep = scenes.FAMILIES["ur5_shelf"], scenes.FAMILIES["mesh_sweep"]
    assert (shelf.cases(100), shelf.cases(2), sweep.cases(100)) == (5, 2, 100)
    jobs = families._jobs(shelf, ("ripm", "ipopt"), 100, 0, 1e-6, 10)
    assert sorted({j.key[0] for j in jobs}) == list(range(5))


def test_scenes_cli_parses_and_names_bad_input_before_any_solve(tmp_path, capsys):
    args = build_parser().parse_args(["bench", "scenes"])
    assert (args.n, args.families, args.tol) == (100, tuple(scenes.FAMILIES), 1e-6)
    out = tmp_path / "scenes"
    assert main(["bench", "scenes", "--families", "kitchen", "--out", str(out)]) == 2
    assert "unknown family 'kitchen'" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.slow
def test_the_profile_splits_an_iteration_and_counts_the_coal_pairs():
    """The panda's profile: the distances take a share of every iteration, the compiled pass
    was asked for pairs, and the section renders every family's row."""
    problem, x0 = maximal_ripm_problem(scenes.panda_boxes_case(0), "via")
    row = profile_solve(problem, x0, RIPMOptions(tol=1e-6, max_iter=500, **LGVI_RIPM_OPTIONS))
    assert row["status"] == "CONVERGED"
    assert 0.0 < row["distances_ms"] < row["per_iter_ms"]
    assert 0.0 < row["distance_share"] < 1.0
    assert row["coal_pairs_per_iter"] > 0 and row["us_per_coal_pair"] > 0
    lines = scenes.profile_markdown({"panda_boxes": row})
    assert lines[-1].startswith("| panda_boxes | CONVERGED |")
    assert len(lines[-1].split("|")) == len(lines[-3].split("|"))
    json.dumps(row)  # a summary entry


def test_a_plan_refused_before_any_solve_is_the_case_failure_not_the_run_end(monkeypatch):
    from mbplan.errors import InfeasibleRequestError

    def refuse(*args, **kwargs):
        raise InfeasibleRequestError("frame goal for 'jaw' is out of reach")

    monkeypatch.setattr(families, "plan_row", refuse)
    monkeypatch.setattr(families, "_workspace", lambda *args: None)
    row = families.solve_case(scenes.FAMILIES["iiwa_distance"], "ripm", 0, 1, 1e-6, 10)
    assert (row["status"], row["success"], row["verified"]) == ("REFUSED", False, False)
    assert row["verification_reasons"] == ["frame goal for 'jaw' is out of reach"]
    assert row["description"].startswith("iiwa")
