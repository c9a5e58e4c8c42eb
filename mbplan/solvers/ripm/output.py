"""What a RIPM solve records and prints: the per-iteration history, IPOPT-like log lines and the
:class:`~mbplan.solvers.result.RIPMResult`."""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

from mbplan.engine.compile_clock import CompileClock
from mbplan.solvers.result import IterationHistory, RIPMResult, RIPMStatus
from mbplan.solvers.ripm.iterate import Iterate, Residuals

_HEADER = "iter    objective    inf_pr   inf_du lg(mu)  ||d||  lg(rg) alpha_du alpha_pr  ls"


@dataclass
class StepRecord:
    """The step that produced the current iterate (zero at the start)."""

    d: float = 0.0  # ‖α dx‖∞
    dw: float = 0.0  # δ_w
    a_du: float = 0.0
    a_pr: float = 0.0
    ls: int = 0  # trial points
    tag: str = " "  # line-search tag, ``r`` in a restoration phase


class Recorder:
    """The history and the log of one solve (``print_level > 0``: printed); its times leave
    out the kernels' compilation (:class:`~mbplan.engine.compile_clock.CompileClock`)."""

    def __init__(self, print_level: int) -> None:
        self.history = IterationHistory()
        self.printing = print_level > 0
        self.clock = CompileClock()

    def _out(self, line: str) -> None:
        print(line, file=sys.stdout)

    def start(self, n: int, n_eq: int, n_ineq: int) -> None:
        self.clock.start()
        if self.printing:
            self._out(f"RIPM: n = {n}, n_eq = {n_eq}, n_ineq = {n_ineq}")
            self._out(_HEADER)

    def record(
        self, iteration: int, objective: float, inf_pr: float, res: Residuals, mu: float,
        last: StepRecord,
    ) -> None:  # fmt: skip
        """One history entry (and log line) for the iterate of ``res``."""
        h = self.history
        restoration = last.tag == "r"
        h.objective.append(float(objective))
        h.inf_pr.append(inf_pr)
        h.inf_du.append(res.inf_du)
        h.kkt_error.append(res.kkt_error)
        h.mu.append(mu)
        h.step_norm.append(last.d)
        h.delta_w.append(last.dw)
        h.alpha_du.append(last.a_du)
        h.alpha_pr.append(last.a_pr)
        h.ls_trials.append(last.ls)
        h.time_s.append(self.clock.elapsed())
        h.restoration.append(restoration)
        if self.printing:
            rg = f"{math.log10(last.dw):5.1f}" if last.dw > 0 else "    -"
            self._out(
                f"{iteration:4d}{'r' if restoration else ' '}{objective:14.7e} {inf_pr:7.2e} "
                f"{res.inf_du:7.2e} {math.log10(mu):5.1f} {last.d:7.2e} {rg} "
                f"{last.a_du:7.2e} {last.a_pr:7.2e}{last.tag}{last.ls:3d}"
            )

    def result(
        self, status: RIPMStatus, message: str, iterations: int, it: Iterate,
        res: Residuals | None, mu: float, counts: tuple[int, int, int],
    ) -> RIPMResult:  # fmt: skip
        """The result at ``it`` (``res`` its residuals, ``None`` if it has no evaluation);
        ``counts``: evaluations, trial evaluations, factorizations."""
        self.clock.stop()
        wall = self.clock.elapsed()
        ok = res is not None
        result = RIPMResult(
            status=status,
            message=message,
            iterations=iterations,
            wall_time_s=wall,
            compile_time_s=self.clock.compile_s,
            x=it.x,
            y=it.y,
            z=it.z,
            s=it.s,
            objective=float(it.ev.objective) if ok else math.nan,
            kkt_error=res.kkt_error if ok else math.inf,
            inf_pr=res.inf_pr if ok else math.inf,
            inf_du=res.inf_du if ok else math.inf,
            mu=mu,
            history=self.history,
            n_evaluations=counts[0],
            n_trial_evaluations=counts[1],
            n_factorizations=counts[2],
        )
        if self.printing:
            self._out(
                f"\nRIPM {status.name}: {message}\n  iterations {iterations}, objective "
                f"{result.objective:.12e}, E_0 {result.kkt_error:.2e}, time {wall:.3f} s "
                f"+ compilation {self.clock.compile_s:.3f} s ({counts[0]} evaluations, {counts[1]} trial evaluations, "
                f"{counts[2]} factorizations)"
            )
        return result
