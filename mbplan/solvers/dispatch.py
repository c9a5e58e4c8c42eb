"""Solve a :class:`~mbplan.solvers.nlp.RIPMProblem` with a solver named by a string."""

from __future__ import annotations

from typing import Any

from mbplan.errors import InputError
from mbplan.solvers.lie_ipm.mlgipm import MLGIPMOptions, solve_mlgipm
from mbplan.solvers.nlp import Point, RIPMProblem
from mbplan.solvers.result import RIPMResult
from mbplan.solvers.ripm.driver import solve_ripm
from mbplan.solvers.ripm.options import RIPMOptions
from mbplan.workspace import Workspace

SOLVERS = {"ripm": (solve_ripm, RIPMOptions), "mlgipm": (solve_mlgipm, MLGIPMOptions)}


def options_for(method: str, **values: Any) -> RIPMOptions | MLGIPMOptions:
    """The options object of solver ``method`` (``"ripm"`` or ``"mlgipm"``)."""
    if method not in SOLVERS:
        raise InputError(f"unknown solver {method!r}; choose from {', '.join(SOLVERS)}")
    return SOLVERS[method][1](**values)


def solve_with(
    method: str,
    problem: RIPMProblem,
    x0: Point,
    options: Any = None,
    workspace: Workspace | None = None,
) -> RIPMResult:
    """``solve_ripm`` or ``solve_mlgipm``; ``options`` of that solver's type or ``None``;
    ``workspace``: the RIPM's (:func:`~mbplan.solvers.ripm.driver.solve_ripm`)."""
    if method not in SOLVERS:
        raise InputError(f"unknown solver {method!r}; choose from {', '.join(SOLVERS)}")
    solve, options_type = SOLVERS[method]
    if options is not None and not isinstance(options, options_type):
        raise InputError(f"{method} takes {options_type.__name__}, got {type(options).__name__}")
    if method == "ripm":
        return solve_ripm(problem, x0, options, workspace=workspace)
    return solve(problem, x0, options)
