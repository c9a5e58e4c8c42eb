"""Small end-to-end runs of the benchmarks (the full runs are committed under benchmarks/results)."""

import json

import numpy as np
import pytest

from mbplan.benchmarks import drone_docking, iiwa_obstacle
from mbplan.cli.main import main
from mbplan.errors import InputError
from mbplan.results import load_npz


@pytest.mark.slow
def test_drone_docking_three_cases_each_method(tmp_path):
    s = drone_docking.run(tmp_path, n=3, seed=0, scaling=False)
    for name in drone_docking.METHODS:
        m = s["methods"][name]
        assert m["n"] == 3
        assert m["converged"] == 3, (name, s["failures"])
    rows = [json.loads(line) for line in (tmp_path / "results.jsonl").read_text().splitlines()]
    assert len(rows) == 9
    # Every solution (through mbplan.plan) passes mbplan.verify: the NumPy LGVI replay.
    assert all(r["verified"] for r in rows)
    assert max(r["replay_deviation"] for r in rows) < 1e-5
    assert (tmp_path / "convergence.png").stat().st_size > 0
    assert "| ripm |" in (tmp_path / "results.md").read_text()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("method", "warm_start", "max_iter", "at_least", "constraint"),
    [
        ("ripm", "linear", 60, 1, "com"),
        ("ripm", "via", 100, 3, "com"),
        ("ipopt", "linear", 500, 2, "com"),
        ("ripm", "via", 100, 1, "distance"),
        ("ipopt", "via", 500, 3, "distance"),
    ],
)
def test_iiwa_small_runs_are_verified(tmp_path, method, warm_start, max_iter, at_least, constraint):
    """Three seeded cases of the real task (the full 100-case run is the benchmark). With the
    linear warm start RIPM fails cases 0 and 2 (links cross the cylinder); the via-point warm
    start solves all three. With coal distances, the RIPM's line search fails on cases 0 and 2
    close to the optimum (see the distance benchmark)."""
    s = iiwa_obstacle.run(
        tmp_path,
        n=3,
        seed=0,
        methods=(method,),
        max_iter=max_iter,
        warm_start=warm_start,
        constraint=constraint,
    )
    assert s["warm_start"] == warm_start and s["obstacle_constraint"] == constraint
    m = s["methods"][method]
    assert m["n"] == 3
    rows = [json.loads(line) for line in (tmp_path / "results.jsonl").read_text().splitlines()]
    # Solved means: the solver succeeded AND the independent replay passed.
    assert m["verified"] == sum(r["success"] and r["verified"] for r in rows)
    assert all(r["verification_reasons"] for r in rows if not r["verified"])
    assert m["verified"] >= at_least, rows


def test_unknown_method_is_named(tmp_path):
    with pytest.raises(InputError, match="unknown method"):
        iiwa_obstacle.run(tmp_path, n=1, methods=("snopt",))


def test_cli_plan_writes_npz(tmp_path, capsys):
    out = tmp_path / "plan.npz"
    code = main(
        [
            "plan",
            "--robot",
            "iiwa",
            "--method",
            "ipopt",
            "--seed",
            "1",
            "--horizon",
            "10",
            "--out",
            str(out),
        ]
    )
    text = capsys.readouterr().out
    assert "verification" in text
    r = load_npz(out)
    assert r.q.shape == (11, 7) and r.tau.shape == (10, 7)
    assert code == (0 if r.success and "passed" in text else 1)
    assert np.all(np.isfinite(r.q))


def test_cli_help_and_errors(capsys):
    assert main([]) == 2
    assert "plan" in capsys.readouterr().out
    assert main(["plan", "--task", "juggling"]) == 2
    assert "unknown task" in capsys.readouterr().err


def test_loops_cli_parses_its_options():
    from mbplan.cli.main import build_parser

    args = build_parser().parse_args(["bench", "loops"])
    assert (args.n, args.seed, args.methods, args.tol, args.max_iter) == (
        10,
        0,
        ("ripm", "ipopt"),
        1e-8,
        500,
    )
    assert args.mechanisms == ("fourbar", "delta", "two_arm_carry")
    given = ["bench", "loops", "--n", "3", "--seed", "4", "--methods", "ipopt"]
    args = build_parser().parse_args([*given, "--mechanisms", "fourbar", "--out", "x"])
    assert (args.n, args.seed, args.methods, args.mechanisms, args.out) == (
        3,
        4,
        ("ipopt",),
        ("fourbar",),
        "x",
    )


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--mechanisms", "stewart"], "unknown mechanism 'stewart'"),
        (["--methods", "snopt"], "unknown method 'snopt'"),
        (["--methods", "fddp"], "fddp cannot plan 'fourbar'"),
        (["--n", "0"], "--n: must be >= 1, got 0"),
    ],
)
def test_loops_bad_input_is_named_before_any_solve(tmp_path, capsys, flags, message):
    out = tmp_path / "loops"
    assert main(["bench", "loops", "--mechanisms", "fourbar", *flags, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not (out / "fourbar.jsonl").exists()


def test_loops_run_refuses_n_below_one(tmp_path):
    from mbplan.benchmarks import families, loops

    with pytest.raises(InputError, match="number of cases"):
        families.run(loops.SUITE, tmp_path, n=0, families=("fourbar",))


@pytest.mark.slow
def test_loops_tiny_fourbar_run_writes_its_files(tmp_path, capsys):
    """Two four-bar cases (the example task and one randomized), both methods, through the
    command line: every row verified, the summary, results.md and the plot written."""
    out = tmp_path / "loops"
    flags = ["--n", "2", "--mechanisms", "fourbar", "--out", str(out)]
    assert main(["bench", "loops", *flags]) == 0
    assert "## fourbar" in capsys.readouterr().out
    rows = [json.loads(line) for line in (out / "fourbar.jsonl").read_text().splitlines()]
    assert sorted((r["case"], r["method"]) for r in rows) == [
        (0, "ipopt"),
        (0, "ripm"),
        (1, "ipopt"),
        (1, "ripm"),
    ]
    assert [r["method"] for r in rows] == ["ripm", "ipopt", "ipopt", "ripm"]  # alternating
    assert all(r["success"] and r["verified"] and r["closure_residual"] < 1e-8 for r in rows)
    s = json.loads((out / "summary.json").read_text())
    fourbar = s["families"]["fourbar"]["methods"]
    assert fourbar["ripm"]["verified"] == fourbar["ipopt"]["verified"] == 2
    assert fourbar["ripm"]["paired_total_ratio"]["cases"] == 2
    assert fourbar["ripm"]["total_ratio"] == pytest.approx(
        fourbar["ripm"]["median_total_time_s"] / fourbar["ipopt"]["median_total_time_s"]
    )
    text = (out / "results.md").read_text()
    assert text.startswith("# Closed-loop") and f"Command: `{s['command']}`" in text
    lines = text.splitlines()
    for i, line in enumerate(lines):  # every table: header, separator and rows alike wide
        if line.startswith("|---"):
            table = [lines[i - 1]]
            for row in lines[i:]:
                if not row.startswith("|"):
                    break
                table.append(row)
            assert len({row.count("|") for row in table}) == 1, table[:2]
    assert (out / "total_time.png").stat().st_size > 0
    assert main(["bench", "loops", *flags]) == 0  # resumed: nothing re-run
    assert "4 of 4 jobs already in" in capsys.readouterr().err
