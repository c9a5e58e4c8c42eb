"""Line-search Riemannian interior point method: Algorithm 1 of the RIPM paper (§VII) with the
globalization of IPOPT (Wächter & Biegler 2006, "WB"): filter line search with switching
condition and second-order correction, inertia correction, multiplier safeguards and an
ℓ1 feasibility restoration phase (WB §3.3) — what the paper's own implementation lacked (§IX).

**Barrier problem** (eq. 49): slacks ``g(x) + s = 0``, ``s > 0``, barrier objective
``φ_μ = f - μ Σ log s``. One multiplier ``z`` serves both ``g + s = 0`` and ``s ≥ 0`` (eq. 50).

The parts, one module each: the iterate and its residuals (:mod:`~mbplan.solvers.ripm.iterate`), the
Newton step with inertia correction (:mod:`~mbplan.solvers.ripm.newton`), the filter line search
(:mod:`~mbplan.solvers.ripm.line_search`), the barrier strategy (:mod:`~mbplan.solvers.ripm.barrier`) and
the restoration phase (:mod:`~mbplan.solvers.ripm.restoration`). This module is the driver: start,
loop, accept, record, stop. ``z`` takes its own fraction-to-boundary step ``α_z`` (WB eq. 15) and
is kept within ``[μ/(κ_Σ s), κ_Σ μ/s]`` (WB eq. 16); termination when ``E_0 ≤ ε_tol``.

Every linear-algebra object is sparse with a fixed pattern; one iteration costs one
``problem.evaluate`` (at the first trial point, with the multipliers it would be accepted with:
usually it is), one ``problem.values`` per further trial and a few sparse LDLᵀ factorizations
(one symbolic analysis per pattern).
"""

from __future__ import annotations

import functools
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from operator import is_
from typing import Any

import numpy as np
import scipy.sparse as sp

from mbplan.engine.jit import announce_uncached_numba
from mbplan.errors import InputError
from mbplan.solvers.kkt.reduced.system import ReducedKKTSystem, kkt_system
from mbplan.solvers.kkt.system import KKTSystem
from mbplan.solvers.nlp import NLPEvaluation, Point, RIPMProblem
from mbplan.solvers.result import IterationHistory, RIPMResult, RIPMStatus
from mbplan.solvers.ripm.barrier import BarrierStrategy
from mbplan.solvers.ripm.iterate import (
    IterateState,
    amax,
    finite,
    transpose_times,
)
from mbplan.solvers.ripm.kernels import RIPM_KERNELS, safeguarded_duals
from mbplan.solvers.ripm.line_search import FilterLineSearch, Search
from mbplan.solvers.ripm.newton import NewtonStep
from mbplan.solvers.ripm.options import RIPMOptions
from mbplan.solvers.ripm.restoration import Restoration, Stop
from mbplan.workspace import Workspace

_HEADER = "iter    objective    inf_pr   inf_du lg(mu)  ||d||  lg(rg) alpha_du alpha_pr  ls"


def solve_ripm(
    problem: RIPMProblem,
    x0: Point,
    options: RIPMOptions | None = None,
    *,
    y0: np.ndarray | None = None,
    z0: np.ndarray | None = None,
    s0: np.ndarray | None = None,
    verbose: bool = False,
    workspace: Workspace | None = None,
    **overrides: Any,
) -> RIPMResult:
    """Solve Problem 2 (eq. 46) from ``x0`` with the RIPM.

    ``options`` defaults to :class:`RIPMOptions` (Table IV); keyword ``overrides`` replace single
    parameters (``solve_ripm(p, x0, tol=1e-8)``). ``y0``, ``z0`` (> 0) and ``s0`` (> 0) warm-start
    the multipliers and slacks. ``verbose=True`` is ``print_level=1``. ``workspace``: where the
    KKT patterns, analyses and reductions are kept (pass one to the solves of a problem family
    to build them once; ``None``: this solve's own; the result is the same).
    """
    opts = options or RIPMOptions()
    if overrides:
        opts = opts.replace(**overrides)
    if verbose and opts.print_level == 0:
        opts = opts.replace(print_level=1)
    return _RIPM(problem, opts, workspace=workspace).run(x0, y0, z0, s0)


# process-wide cache, result-neutral: prints a first-run line only
@functools.cache
def _announce_uncached_kernels() -> None:
    """The first-run line if the iteration's numba kernels are not cached yet (once per
    process)."""
    announce_uncached_numba(*RIPM_KERNELS)


@dataclass
class _Shared:
    """What the main phase and a restoration phase share: counters, log, KKT system."""

    kkt: KKTSystem | ReducedKKTSystem
    history: IterationHistory
    out: Callable[[str], None] | None
    t0: float = 0.0
    iter: int = 0
    n_eval: int = 0
    n_values: int = 0
    counts: dict[str, int] = field(default_factory=dict)


class _RIPM(IterateState, NewtonStep, FilterLineSearch, BarrierStrategy, Restoration):
    """State of one solve (or of one restoration phase, ``parent`` given)."""

    def __init__(
        self,
        problem: RIPMProblem,
        options: RIPMOptions,
        parent: _RIPM | None = None,
        workspace: Workspace | None = None,
    ) -> None:
        self.p, self.o = problem, options
        self.n, self.me, self.mi = int(problem.n), int(problem.n_eq), int(problem.n_ineq)
        self.m = self.me + self.mi
        self.parent = parent
        self.resto = parent is not None
        if parent is None:
            _announce_uncached_kernels()
            out = (lambda line: print(line, file=sys.stdout)) if options.print_level > 0 else None
            kkt = kkt_system(
                problem,
                options.kkt_method,
                options.kkt_ordering,
                options.kkt_pivot_threshold,
                workspace,
            )
            self.sh = _Shared(kkt, IterationHistory(), out)
        else:
            self.sh = parent.sh
        # the phase: σ f + ρ Σ(p + n) + ζ/2 ‖ξ‖² (σ = 1, no elastics in the main phase)
        self.sigma = 0.0 if self.resto else 1.0
        self.rho = options.resto_penalty
        self.zeta = 0.0
        self.delta_w_last = 0.0
        self.n_perturbed = 0  # consecutive iterations that needed δ_w > 0
        self.soft_steps = 0  # steps of the current soft restoration phase (0: not in one)
        self.filter: list[tuple[float, float]] = []
        self.ep = self.en = self.zp = self.zn = self.xi = None
        # describes the step that produced the current iterate (for the log and history)
        self.last = {"d": 0.0, "dw": 0.0, "a_du": 0.0, "a_pr": 0.0, "ls": 0, "tag": " "}
        self.free_mode = options.mu_strategy == "adaptive" and parent is None
        self.kkt_refs: list[float] = []
        self.mu_max = math.inf
        self.probe_pending = False  # Mehrotra's μ is due once the step's matrix is factorized
        self.compl_shift: np.ndarray | None = None  # Mehrotra's corrector ΔS_aff Δz_aff
        self.measured: tuple = (None,) * 4  # ev, y, z, s of the last _measures

    @property
    def kkt(self) -> KKTSystem | ReducedKKTSystem:
        return self.sh.kkt

    @property
    def iter(self) -> int:
        return self.sh.iter

    def _count(self, key: str) -> None:
        self.sh.counts[key] = self.sh.counts.get(key, 0) + 1

    # ------------------------------------------------------------------ start
    def _initialize(self, x0: Point, y0, z0, s0) -> None:
        """The starting iterate: the evaluation with the Hessian at ``y0`` (0 unless given), the
        slacks from it, ``y`` by least squares with its Jacobian (WB) unless given; a kept
        least-squares ``y`` is evaluated again (the Hessian of the Lagrangian depends on it)."""
        o = self.o
        self.mu = o.mu_init
        self.tau = max(o.tau_min, 1 - self.mu)
        self.x = x0
        self.y = np.zeros(self.me) if y0 is None else np.asarray(y0, dtype=float)
        self.z = np.full(self.mi, o.bound_mult_init_val) if z0 is None else np.asarray(z0, float)
        self.s = np.ones(self.mi) if s0 is None else np.asarray(s0, dtype=float)
        shapes = (self.y.shape, self.z.shape, self.s.shape)
        if shapes != ((self.me,), (self.mi,), (self.mi,)):
            raise InputError(
                f"y0, z0, s0 have shapes {shapes}; expected ({self.me},), ({self.mi},) x2"
            )
        # the defaults are finite and positive (the options are validated)
        if (y0 is not None and not finite(self.y)) or any(
            a0 is not None and (not finite(a) or np.any(a <= 0))
            for a, a0 in ((self.z, z0), (self.s, s0))
        ):
            raise InputError("s0 and z0 must be finite and positive, y0 finite")
        self.ev = self._evaluate(x0, self.y, self.z)
        if self.ev is None:
            raise Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at the initial point")
        if s0 is None and self.mi > 0:
            self.s = np.maximum(-self.ev.ineq, o.bound_push)
        if y0 is None and self.me > 0 and o.constr_mult_init_max > 0:
            self.y = self._least_squares_y(self.ev)
            if self.y is not None:  # kept: the Hessian of the Lagrangian with it
                self.ev = self._evaluate(x0, self.y, self.z)
                if self.ev is None:
                    raise Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at y0")
            else:
                self.y = np.zeros(self.me)
        theta0 = self._current_trial().theta
        self.mu_max = max(o.mu_init, o.mu_max_fact * self._avg_compl())
        self.theta_max = o.theta_max_fact * max(1.0, theta0)
        self.theta_min = o.theta_min_fact * max(1.0, theta0)

    def _least_squares_y(self, ev: NLPEvaluation) -> np.ndarray | None:
        """``y`` minimizing ``‖grad f + A_Eᵀy + A_Iᵀz‖`` (WB); ``None`` if it is larger than
        ``constr_mult_init_max`` (or not computable): ``y = 0`` then. Solved with the Newton
        step's own system and pattern (its symbolic phase and reduction serve both): ``H`` and
        ``A_I`` with zero values, ``I`` on the primal diagonal, ``-I`` on the inequality rows
        (it overwrites the system's matrices and factorization: every Newton step sets its own
        first; with ``kkt_method="reduced"`` a plan the reduction cannot use raises here, at the
        start)."""
        kkt, n, me = self.kkt, self.n, self.me
        kkt.set_matrices(
            _zero_values(ev.hessian_lower), ev.eq_jacobian, _zero_values(ev.ineq_jacobian)
        )
        diag = np.zeros(n + self.m)
        diag[:n] = 1.0
        diag[n + me :] = -1.0
        inertia = kkt.factorize(diag, self.o.static_regularization)
        if inertia is None or inertia.zero or inertia.negative != self.m:
            return None
        rhs = np.zeros(n + self.m)
        np.negative(ev.gradient + transpose_times(ev.ineq_jacobian, self.z), out=rhs[:n])
        sol, _ = kkt.solve(rhs, self.o.max_refinement_steps, self.o.residual_ratio_max)
        y = sol[n : n + me]
        return y if finite(y) and amax(y) <= self.o.constr_mult_init_max else None

    # ------------------------------------------------------------------ loop
    def run(self, x0: Point, y0, z0, s0) -> RIPMResult:
        self.sh.t0 = time.perf_counter()
        if self.sh.out:
            self.sh.out(f"RIPM: n = {self.n}, n_eq = {self.me}, n_ineq = {self.mi}")
            self.sh.out(_HEADER)
        try:
            self._initialize(x0, y0, z0, s0)
            self._iterate()
        except Stop as stop:
            return self._result(stop.status, stop.message)
        raise AssertionError("unreachable")  # pragma: no cover

    def _check_main(self, n_acceptable: int) -> int:
        """Termination tests of the main phase; returns the count of acceptable iterates."""
        o = self.o
        if self.kkt_error <= o.tol:
            raise Stop(RIPMStatus.CONVERGED)
        n_acceptable = n_acceptable + 1 if self.kkt_error <= o.acceptable_tol else 0
        if n_acceptable >= o.acceptable_iter:
            raise Stop(RIPMStatus.ACCEPTABLE, f"E_0 ≤ acceptable_tol for {n_acceptable} iterations")
        if self.iter >= o.max_iter:
            raise Stop(RIPMStatus.MAX_ITER)
        return n_acceptable

    def _iterate(self) -> None:
        """The iterations of a phase: returns only when a restoration phase is done."""
        o = self.o
        n_acceptable, tiny_step, first = 0, False, True
        while True:
            self._measures()
            if self.resto:
                if self._check_resto(first):
                    return  # the main phase records this iterate
                if not first:
                    self._record(self.ev.objective, self._original_measures()[2])
            else:
                self._record(self.ev.objective)
                n_acceptable = self._check_main(n_acceptable)
            first = False
            if self._update_barrier(tiny_step):
                if self.resto and self.kkt_error <= o.acceptable_tol:
                    self._resto_converged()
                ok = self.kkt_error <= o.acceptable_tol
                raise Stop(
                    RIPMStatus.ACCEPTABLE if ok else RIPMStatus.NUMERICAL_ERROR,
                    "search direction became too small to make progress",
                )
            self.cur = self._current_trial()
            mu = self.mu
            computed = self._newton_step()
            if computed is None:
                self._fail_or_restore("inertia correction failed (δ_w > δ_w,max)")
                continue
            step, dw = computed
            if self.mu != mu:  # φ_μ with the step's μ (probing sets it, in the main phase)
                self.cur.phi = self.sigma * self.cur.f - self.mu * self.cur.log_s
            tiny_step = (
                self.inf_pr < 1e-4
                and max(amax(step.dx), amax(step.ds / (1 + self.s))) < o.tiny_step_tol
            )
            if tiny_step:  # IPOPT's tiny-step rule: accept the full step without line search
                alpha = self._alpha_max(step)
                trial = self._trial_at(step, alpha, evaluate=not self.resto)
                search = Search(trial, step, alpha, 1, "T", all_nan=trial is None)
            elif self.soft_steps:  # in IPOPT's soft restoration phase
                search = self._soft_restoration(step)
            else:
                search = self._line_search(step, self.cur)
                if search.trial is None and not search.all_nan:
                    search = self._soft_restoration(step)
            if search.trial is None:
                if search.all_nan:
                    raise Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite values at every trial point")
                self._fail_or_restore("line search failed")
                continue
            self._accept(search, dw)

    def _fail_or_restore(self, why: str) -> None:
        """After a failed step: stop, or start the restoration phase (main phase, with
        inequality or equality rows, not at an almost feasible point: IPOPT's rules)."""
        if self.resto:
            if self.kkt_error <= self.o.acceptable_tol:  # solved to the acceptable level
                self._resto_converged()
            raise Stop(RIPMStatus.LINE_SEARCH_FAILED, f"restoration phase: {why}")
        if self.m == 0 or not self.o.restoration:
            status = (
                RIPMStatus.NUMERICAL_ERROR if "inertia" in why else RIPMStatus.LINE_SEARCH_FAILED
            )
            raise Stop(status, why)
        if self.inf_pr <= min(1e-2 * self.o.tol, 0.1 * self.o.constr_viol_tol):
            # IPOPT's rule: the restoration phase cannot reduce an infeasibility this small
            raise Stop(
                RIPMStatus.LINE_SEARCH_FAILED,
                f"{why} at an almost feasible point (‖c‖∞ = {self.inf_pr:.1e}): no restoration",
            )
        self._restoration()

    def _accept(self, search: Search, dw: float) -> None:
        """Take the step: primal with α, ``y`` with α, ``z`` with its own α_z (WB eq. 15-16)."""
        o = self.o
        trial, step, alpha = search.trial, search.step, search.alpha
        if search.tag[0] == "h":
            self._augment_filter(self.cur.theta, self.cur.phi)
        s, ev = trial.s, trial.ev  # evaluated with its multipliers by the line search
        y, z, alpha_z = trial.multipliers or self._multipliers_at(step, alpha, s)
        if self.resto:
            p, n = trial.p, trial.n
            self.zp = safeguarded_duals(self.zp, step.dzp, alpha_z, p, self.mu, o.kappa_sigma)
            self.zn = safeguarded_duals(self.zn, step.dzn, alpha_z, n, self.mu, o.kappa_sigma)
            self.ep, self.en, self.xi = p, n, trial.xi
        if ev is None:
            ev = self._evaluate(trial.x, y, z)
            if ev is None:
                raise Stop(
                    RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at the accepted point"
                )
        self.x, self.s, self.y, self.z, self.ev = trial.x, s, y, z, ev
        self.sh.iter += 1
        self.last = {
            "d": alpha * amax(step.dx),  # = ‖α dx‖∞ exactly (α > 0)
            "dw": dw,
            "a_du": alpha_z,
            "a_pr": alpha,
            "ls": search.trials,
            "tag": "r" if self.resto else search.tag[0],
        }

    # ------------------------------------------------------------------ output
    def _record(self, objective: float, inf_pr: float | None = None) -> None:
        h, last = self.sh.history, self.last
        restoration = last["tag"] == "r"
        inf_pr = self.inf_pr if inf_pr is None else inf_pr
        h.objective.append(float(objective))
        h.inf_pr.append(inf_pr)
        h.inf_du.append(self.inf_du)
        h.kkt_error.append(self.kkt_error)
        h.mu.append(self.mu)
        h.step_norm.append(last["d"])
        h.delta_w.append(last["dw"])
        h.alpha_du.append(last["a_du"])
        h.alpha_pr.append(last["a_pr"])
        h.ls_trials.append(last["ls"])
        h.time_s.append(time.perf_counter() - self.sh.t0)
        h.restoration.append(restoration)
        if self.sh.out:
            rg = f"{math.log10(last['dw']):5.1f}" if last["dw"] > 0 else "    -"
            self.sh.out(
                f"{self.iter:4d}{'r' if restoration else ' '}{objective:14.7e} {inf_pr:7.2e} "
                f"{self.inf_du:7.2e} {math.log10(self.mu):5.1f} {last['d']:7.2e} {rg} "
                f"{last['a_du']:7.2e} {last['a_pr']:7.2e}{last['tag']}{last['ls']:3d}"
            )

    def _result(self, status: RIPMStatus, message: str) -> RIPMResult:
        wall = time.perf_counter() - self.sh.t0
        ok = getattr(self, "ev", None) is not None
        if ok and not all(map(is_, self.measured, (self.ev, self.y, self.z, self.s))):
            self._measures()  # stopped after the iterate moved
        result = RIPMResult(
            status=status,
            message=message,
            iterations=self.iter,
            wall_time_s=wall,
            x=self.x,
            y=self.y,
            z=self.z,
            s=self.s,
            objective=float(self.ev.objective) if ok else math.nan,
            kkt_error=self.kkt_error if ok else math.inf,
            inf_pr=self.inf_pr if ok else math.inf,
            inf_du=self.inf_du if ok else math.inf,
            mu=self.mu,
            history=self.sh.history,
            n_evaluations=self.sh.n_eval,
            n_trial_evaluations=self.sh.n_values,
            n_factorizations=self.kkt.n_factorizations,
        )
        if self.sh.out:
            self.sh.out(
                f"\nRIPM {status.name}: {message}\n  iterations {self.iter}, objective "
                f"{result.objective:.12e}, E_0 {result.kkt_error:.2e}, time {wall:.3f} s "
                f"({self.sh.n_eval} evaluations, {self.sh.n_values} trial evaluations, "
                f"{self.kkt.n_factorizations} factorizations)"
            )
        return result


def _zero_values(matrix: sp.spmatrix) -> sp.csr_matrix:
    """``matrix``'s pattern with zero values."""
    m = sp.csr_matrix(matrix)
    return sp.csr_matrix((np.zeros_like(m.data), m.indices, m.indptr), shape=m.shape)
