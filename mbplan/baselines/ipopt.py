"""What the IPOPT baselines share: checked options and the statistics they report of a solve."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mbplan.validation import as_int, as_real

# CasADi timers of the function and derivative evaluations (``t_wall_<name>`` in ``stats()``).
EVAL_TIMERS = ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l")


def base_options(max_iter: object, tol: object) -> dict[str, Any]:
    """IPOPT options (no ``ipopt.`` prefix) of both baselines: checked ``max_iter >= 0`` and
    ``tol > 0``, exact Hessian, MUMPS, no output."""
    return {
        "max_iter": as_int(max_iter, "max_iter", minimum=0, what="iteration limit"),
        "tol": as_real(tol, "tol", positive=True),
        "linear_solver": "mumps",
        "hessian_approximation": "exact",
        "print_level": 0,
        "sb": "yes",
    }


@dataclass(frozen=True, eq=False)
class IpoptStats:
    """IPOPT's return status, iteration count, primal/dual infeasibility per iteration (iteration
    0 first) and wall times [s] of the whole solve and of its function evaluations."""

    status: str
    iterations: int
    inf_pr: np.ndarray
    inf_du: np.ndarray
    solve_time: float
    eval_time: float

    @classmethod
    def of(cls, stats: Mapping[str, Any]) -> IpoptStats:
        """Read ``solver.stats()`` of a CasADi ``nlpsol`` built with ``record_time``."""
        history = stats.get("iterations", {})
        return cls(
            status=str(stats["return_status"]),
            iterations=int(stats["iter_count"]),
            inf_pr=np.asarray(history.get("inf_pr", []), dtype=float),
            inf_du=np.asarray(history.get("inf_du", []), dtype=float),
            solve_time=float(stats["t_wall_total"]),
            eval_time=sum(float(stats.get(f"t_wall_{name}", 0.0)) for name in EVAL_TIMERS),
        )

    @property
    def time_per_iteration(self) -> float:
        return self.solve_time / max(self.iterations, 1)

    @property
    def solver_time_per_iteration(self) -> float:
        """Time per iteration without the function evaluations (the metric of Tables II, III)."""
        return (self.solve_time - self.eval_time) / max(self.iterations, 1)
