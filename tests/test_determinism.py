"""A solve's result depends on its problem alone: not on what the process solved before it, nor
on the order of the solves, with or without a shared workspace (the joint reduction of the
iiwa with coal distances picks its pivots on reference values that every case shares, and
the cases share its symbolic phase through the workspace)."""

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from mbplan.solvers import RIPMResult, solve_ripm
from mbplan.tasks.speed import TASKS
from mbplan.workspace import Workspace

TASK = "iiwa-distance"
CASES = (0, 1, 2)  # case 0 after 1 and 2 took 27 iterations, alone 28, with process-wide picks


def fingerprint(result: RIPMResult) -> str:
    """A digest of the iteration history (wall times aside), the final iterate and multipliers,
    bit for bit."""
    digest = hashlib.sha256(f"{result.status.name} {result.iterations}".encode())
    for name, values in sorted(result.history.arrays().items()):
        if name != "time_s":
            digest.update(name.encode() + np.ascontiguousarray(values).tobytes())
    for name in sorted(result.x):
        digest.update(name.encode() + np.ascontiguousarray(result.x[name]).tobytes())
    for values in (result.y, result.z, result.s):
        digest.update(np.ascontiguousarray(values).tobytes())
    return digest.hexdigest()


def solve(case: int, workspace: Workspace | None = None) -> RIPMResult:
    problem, x0, options = TASKS[TASK](case)
    return solve_ripm(problem, x0, options, workspace=workspace)


def test_a_case_in_process_after_others_equals_the_case_in_a_fresh_process():
    script = (
        f"from test_determinism import fingerprint, solve\nprint(fingerprint(solve({CASES[0]})))\n"
    )
    root = Path(__file__).resolve().parents[1]
    path = os.pathsep.join([str(root / "tests"), str(root), os.environ.get("PYTHONPATH", "")])
    fresh = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
        env={**os.environ, "PYTHONPATH": path},
    ).stdout.split()[-1]
    for case in CASES[1:]:
        solve(case)
    assert fingerprint(solve(CASES[0])) == fresh


def test_cases_solved_in_two_orders_with_a_shared_workspace_give_the_same_results():
    results = {}
    for order in (CASES, CASES[::-1]):
        ws = Workspace()
        results[order] = {case: fingerprint(solve(case, ws)) for case in order}
        assert ws.count("reduction") == 1  # the reduced KKT path, one pick shared by the cases
    forward, backward = results.values()
    assert forward == backward
    assert forward == {case: fingerprint(solve(case)) for case in CASES}  # each alone
