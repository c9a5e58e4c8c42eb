"""Line-search Riemannian interior point method: Algorithm 1 of the RIPM paper (§VII) with the
globalization of IPOPT (Wächter & Biegler 2006, "WB"): filter line search with switching
condition and second-order correction, inertia correction, multiplier safeguards and an
ℓ1 feasibility restoration phase (WB §3.3) — what the paper's own implementation lacked (§IX).

**Barrier problem** (eq. 49): slacks ``g(x) + s = 0``, ``s > 0``, barrier objective
``φ_μ = f - μ Σ log s``. One multiplier ``z`` serves both ``g + s = 0`` and ``s ≥ 0`` (eq. 50).

The components, one module each, constructed with their options group and called with explicit
arguments: the barrier problem of a phase with its iterate and residuals
(:mod:`~mbplan.solvers.ripm.iterate`), the Newton step with inertia correction
(:mod:`~mbplan.solvers.ripm.newton`), the filter line search (:mod:`~mbplan.solvers.ripm.line_search`),
the barrier strategy (:mod:`~mbplan.solvers.ripm.barrier`) and the restoration phases
(:mod:`~mbplan.solvers.ripm.restoration`). This module is the driver: start, loop, accept,
record, stop. ``z`` takes its own fraction-to-boundary step ``α_z`` (WB eq. 15) and
is kept within ``[μ/(κ_Σ s), κ_Σ μ/s]`` (WB eq. 16); termination when ``E_0 ≤ ε_tol``.

Every linear-algebra object is sparse with a fixed pattern; one iteration costs one
``problem.evaluate`` (at the first trial point, with the multipliers it would be accepted with:
usually it is), one ``problem.values`` per further trial and a few sparse LDLᵀ factorizations
(one symbolic analysis per pattern).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from mbplan.errors import InputError
from mbplan.solvers.kkt.reduced.system import ReducedKKTSystem, kkt_system
from mbplan.solvers.kkt.system import KKTSystem
from mbplan.solvers.nlp import NLPEvaluation, Point, RIPMProblem
from mbplan.solvers.result import RIPMResult, RIPMStatus
from mbplan.solvers.ripm.barrier import BarrierStrategy
from mbplan.solvers.ripm.iterate import Iterate, Residuals, Step, Stop, Trial, amax, finite
from mbplan.solvers.ripm.kernels import safeguarded_duals
from mbplan.solvers.ripm.line_search import FilterLineSearch, Search
from mbplan.solvers.ripm.newton import NewtonStep
from mbplan.solvers.ripm.options import RIPMOptions
from mbplan.solvers.ripm.output import Recorder, StepRecord
from mbplan.solvers.ripm.phase import Counters, Phase
from mbplan.solvers.ripm.restoration import Restoration, SoftRestoration
from mbplan.workspace import Workspace


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
    return _main_phase(problem, opts, workspace).run(x0, y0, z0, s0)


@dataclass
class _Shared:
    """What the main phase and a restoration phase share: KKT system, counters, record."""

    kkt: KKTSystem | ReducedKKTSystem
    counters: Counters
    recorder: Recorder
    iter: int = 0


def _main_phase(
    problem: RIPMProblem, o: RIPMOptions, workspace: Workspace | None = None
) -> _Iterations:
    """The main phase of a solve of ``problem`` with its components (the KKT system's symbolic
    work kept in ``workspace``)."""
    lin, term, bar = o.linear_solver, o.termination, o.barrier
    kkt = kkt_system(problem, lin.kkt_method, lin.kkt_ordering, lin.kkt_pivot_threshold, workspace)
    sh = _Shared(kkt, Counters(), Recorder(o.output.print_level))
    phase = Phase(problem, sh.counters, o.line_search, term.s_max)
    barrier = BarrierStrategy(bar, term.tol, bar.mu_init, bar.mu_strategy == "adaptive")
    restoration = Restoration(
        o.restoration_phase, phase, bar.tau_min, term.tol, term.constr_viol_tol
    )
    return _Iterations(sh, phase, o, barrier, restoration)


class _Iterations:
    """The iterations of one phase: the main phase, or a restoration phase (``original``: the
    main phase's filter and μ, which decide when it returns)."""

    def __init__(
        self,
        sh: _Shared,
        phase: Phase,
        options: RIPMOptions,
        barrier: BarrierStrategy,
        restoration: Restoration,
        original: tuple[FilterLineSearch, float] | None = None,
    ) -> None:
        self.sh, self.phase, self.o, self.barrier = sh, phase, options, barrier
        self.restoration, self.original = restoration, original
        self.newton = NewtonStep(sh.kkt, phase, options.inertia, options.linear_solver)
        self.soft = SoftRestoration(
            options.restoration_phase, phase, options.line_search.kappa_sigma
        )
        self.it: Iterate | None = None
        self.res: Residuals | None = None
        self.filter: FilterLineSearch | None = None
        self.cur: Trial | None = None  # the iterate as a trial point of the current step
        self.last = StepRecord()

    # ------------------------------------------------------------------ start
    def _initialize(self, x0: Point, y0, z0, s0) -> None:
        """The starting iterate: the evaluation with the Hessian at ``y0`` (0 unless given), the
        slacks from it, ``y`` by least squares with its Jacobian (WB) unless given; a kept
        least-squares ``y`` is evaluated again (the Hessian of the Lagrangian depends on it)."""
        init, ph = self.o.initialization, self.phase
        y = np.zeros(ph.me) if y0 is None else np.asarray(y0, dtype=float)
        z = np.full(ph.mi, init.bound_mult_init_val) if z0 is None else np.asarray(z0, float)
        s = np.ones(ph.mi) if s0 is None else np.asarray(s0, dtype=float)
        if (y.shape, z.shape, s.shape) != ((ph.me,), (ph.mi,), (ph.mi,)):
            raise InputError(
                f"y0, z0, s0 have shapes {(y.shape, z.shape, s.shape)}; expected ({ph.me},), "
                f"({ph.mi},) x2"
            )
        # the defaults are finite and positive (the options are validated)
        if (y0 is not None and not finite(y)) or any(
            a0 is not None and (not finite(a) or np.any(a <= 0)) for a, a0 in ((z, z0), (s, s0))
        ):
            raise InputError("s0 and z0 must be finite and positive, y0 finite")
        it = self.it = Iterate(x0, s, y, z)
        it.ev = ph.evaluate(x0, y, z)
        if it.ev is None:
            raise Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at the initial point")
        if s0 is None and ph.mi > 0:
            it.s = np.maximum(-it.ev.ineq, init.bound_push)
        if y0 is None and ph.me > 0 and init.constr_mult_init_max > 0:
            y_ls = self._least_squares_y(it.ev, it.z)
            if y_ls is not None:  # kept: the Hessian of the Lagrangian with it
                it.y = y_ls
                it.ev = ph.evaluate(x0, it.y, it.z)
                if it.ev is None:
                    raise Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at y0")
        theta0 = ph.current(it, self.barrier.mu).theta
        self.barrier.start(it.s, it.z)
        self.filter = FilterLineSearch(self.o.line_search, theta0)

    def _least_squares_y(self, ev: NLPEvaluation, z: np.ndarray) -> np.ndarray | None:
        return self.newton.least_squares_y(ev, z, self.o.initialization.constr_mult_init_max)

    # ------------------------------------------------------------------ loop
    def run(self, x0: Point, y0, z0, s0) -> RIPMResult:
        """The solve from ``x0`` (``y0, z0, s0``: given multipliers and slacks, or ``None``)."""
        self.sh.recorder.start(self.phase.n, self.phase.me, self.phase.mi)
        try:
            self._initialize(x0, y0, z0, s0)
            self._iterate()
        except Stop as stop:
            return self._result(stop.status, stop.message)
        finally:
            self.sh.recorder.clock.stop()  # also when an error or an interrupt ends the solve
        raise AssertionError("unreachable")  # pragma: no cover

    def _iterate(self) -> None:
        """The iterations of a phase (RIPM Algorithm 1 with WB's globalization): returns only
        when a restoration phase is done."""
        term, ph, barrier = self.o.termination, self.phase, self.barrier
        n_acceptable, tiny_step, first = 0, False, True
        while True:
            it = self.it
            res = self.res = ph.measures(it, barrier.mu)
            if self.original is None:
                self._record(it.ev.objective)
                n_acceptable = self._check_main(n_acceptable)
            elif self._restoration_done(first):
                return  # the main phase records this iterate
            first = False
            error_at = functools.partial(ph.error, it, res)
            stuck = barrier.update(res.kkt_error, error_at, tiny_step, it.s, it.z)
            self._sync_filter()
            if stuck:
                ok = res.kkt_error <= term.acceptable_tol
                if self.original is not None and ok:
                    self.restoration.converged(it)
                raise Stop(
                    RIPMStatus.ACCEPTABLE if ok else RIPMStatus.NUMERICAL_ERROR,
                    "search direction became too small to make progress",
                )
            self.cur = ph.current(it, barrier.mu)
            computed = self._newton_step()
            if computed is None:
                self._fail_or_restore("inertia correction failed (δ_w > δ_w,max)")
                continue
            step, dw = computed
            tiny_step = (
                res.inf_pr < 1e-4
                and max(amax(step.dx), amax(step.ds / (1 + it.s)))
                < self.o.line_search.tiny_step_tol
            )
            search = self._search(step, tiny_step)
            if search.trial is None:
                if search.all_nan:
                    raise Stop(RIPMStatus.NUMERICAL_ERROR, "non-finite values at every trial point")
                self._fail_or_restore("line search failed")
                continue
            self._accept(search, dw)

    def _check_main(self, n_acceptable: int) -> int:
        """Termination tests of the main phase; returns the count of acceptable iterates."""
        term, error = self.o.termination, self.res.kkt_error
        if error <= term.tol:
            raise Stop(RIPMStatus.CONVERGED)
        n_acceptable = n_acceptable + 1 if error <= term.acceptable_tol else 0
        if n_acceptable >= term.acceptable_iter:
            raise Stop(RIPMStatus.ACCEPTABLE, f"E_0 ≤ acceptable_tol for {n_acceptable} iterations")
        if self.sh.iter >= term.max_iter:
            raise Stop(RIPMStatus.MAX_ITER)
        return n_acceptable

    def _restoration_done(self, first: bool) -> bool:
        """Termination tests of a restoration phase (``True``: back to the main phase); records
        its iterate otherwise."""
        main_filter, main_mu = self.original
        it = self.it
        if self.restoration.done(it, self.res.kkt_error, first, main_mu, main_filter):
            return True
        if self.sh.iter >= self.o.termination.max_iter:
            raise Stop(RIPMStatus.MAX_ITER)
        if not first:
            self._record(it.ev.objective, self.restoration.original_measures(it, main_mu)[2])
        return False

    def _sync_filter(self) -> None:
        """Empty the filter if the barrier problem changed (WB)."""
        if self.barrier.filter_reset:
            self.barrier.filter_reset = False
            self.filter.reset()

    def _newton_step(self) -> tuple[Step, float] | None:
        """The Newton step with Mehrotra's probing μ when due; ``φ_μ`` of the current point
        with the step's μ."""
        it, barrier, cur = self.it, self.barrier, self.cur
        mu = barrier.mu
        probe = (lambda aff: barrier.probe(it.s, it.z, aff)) if barrier.probe_pending else None
        corrector = self.o.barrier.corrector and not self.phase.resto
        computed = self.newton.compute(it, self.res, mu, barrier.tau, probe, corrector)
        self._sync_filter()
        if computed is not None:
            barrier.probe_pending = False
            if barrier.mu != mu:
                cur.phi = self.phase.sigma * cur.f - barrier.mu * cur.log_s
        return computed

    def _search(self, step: Step, tiny_step: bool) -> Search:
        """The accepted trial along ``step``: the full step if tiny (IPOPT), else the filter
        line search, and IPOPT's soft restoration where that fails or is under way."""
        it, ph, mu, tau = self.it, self.phase, self.barrier.mu, self.barrier.tau
        if tiny_step:
            alpha = ph.alpha_max(it, step, tau)
            trial = ph.trial_at(it, step, alpha, mu, tau, evaluate=True)
            return Search(trial, step, alpha, 1, "T", all_nan=trial is None)
        if self.soft.steps:
            return self._soft_step(step)
        search = self.filter.search(
            self.cur,
            step,
            ph.slope(it, step, mu),
            lambda d: ph.alpha_max(it, d, tau),
            lambda d, alpha, evaluate: ph.trial_at(it, d, alpha, mu, tau, evaluate),
            self.newton.correction,
            self.res.r_c,
        )
        if search.trial is None and not search.all_nan:
            return self._soft_step(step)
        return search

    def _soft_step(self, step: Step) -> Search:
        b = self.barrier
        return self.soft.step(self.it, self.cur, step, self.filter, b.mu, b.tau, b.free_mode)

    def _fail_or_restore(self, why: str) -> None:
        """After a failed step: stop, or start the restoration phase (main phase, with
        inequality or equality rows, not at an almost feasible point: IPOPT's rules)."""
        o, res = self.o, self.res
        if self.original is not None:
            if res.kkt_error <= o.termination.acceptable_tol:  # solved to the acceptable level
                self.restoration.converged(self.it)
            raise Stop(RIPMStatus.LINE_SEARCH_FAILED, f"restoration phase: {why}")
        if self.phase.m == 0 or not o.restoration_phase.restoration:
            status = (
                RIPMStatus.NUMERICAL_ERROR if "inertia" in why else RIPMStatus.LINE_SEARCH_FAILED
            )
            raise Stop(status, why)
        if res.inf_pr <= min(1e-2 * o.termination.tol, 0.1 * o.termination.constr_viol_tol):
            # IPOPT's rule: the restoration phase cannot reduce an infeasibility this small
            raise Stop(
                RIPMStatus.LINE_SEARCH_FAILED,
                f"{why} at an almost feasible point (‖c‖∞ = {res.inf_pr:.1e}): no restoration",
            )
        self._restore()

    def _restore(self) -> None:
        """Run the ℓ1 restoration phase (WB §3.3) and continue from its result."""
        o, rest = self.o, self.restoration
        if not self.soft.steps:  # else augmented when the soft restoration phase started
            self.filter.augment(self.cur.theta, self.cur.phi)
        self.soft.steps = 0
        phase = rest.phase()
        start, mu, theta0 = rest.start(phase, self.it, self.barrier.mu)
        barrier = BarrierStrategy(o.barrier, o.termination.tol, mu, adaptive=False)
        child = _Iterations(self.sh, phase, o, barrier, rest, (self.filter, self.barrier.mu))
        child.it = start
        try:
            if start.ev is None:
                raise Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
            child.filter = FilterLineSearch(o.line_search, theta0)
            child._iterate()
        except Stop:
            self._leave(child, keep_multipliers=True)
            raise
        self._leave(child, keep_multipliers=False)
        self.last = child.last
        self.barrier.kkt_refs = []

    def _leave(self, child: _Iterations, keep_multipliers: bool) -> None:
        """Continue from the restoration phase's iterate; with ``resto_ls_multipliers``, ``y``
        by least squares (IPOPT's ``constr_mult_reset_threshold > 0``)."""
        it = self.restoration.leave(child.it, self.barrier.mu, keep_multipliers)
        if it is None:
            return
        self.it = it
        if not keep_multipliers and self.o.restoration_phase.resto_ls_multipliers and self.phase.me:
            y_ls = self._least_squares_y(it.ev, it.z)
            if y_ls is not None and np.any(y_ls):
                it.y = y_ls
                ev = self.phase.evaluate(it.x, it.y, it.z)
                if ev is None:
                    raise Stop(RIPMStatus.NUMERICAL_ERROR, "restoration: non-finite derivatives")
                it.ev = ev

    def _accept(self, search: Search, dw: float) -> None:
        """Take the step: primal with α, ``y`` with α, ``z`` with its own α_z (WB eq. 15-16)."""
        ph, mu, it = self.phase, self.barrier.mu, self.it
        trial, step, alpha = search.trial, search.step, search.alpha
        if search.tag[0] == "h":
            self.filter.augment(self.cur.theta, self.cur.phi)
        s, ev = trial.s, trial.ev  # evaluated with its multipliers by the line search
        y, z, alpha_z = trial.multipliers or ph.multipliers_at(
            it, step, alpha, s, mu, self.barrier.tau
        )
        new = Iterate(trial.x, s, y, z, ev)
        if ph.resto:
            kappa = self.o.line_search.kappa_sigma
            new.zp = safeguarded_duals(it.zp, step.dzp, alpha_z, trial.p, mu, kappa)
            new.zn = safeguarded_duals(it.zn, step.dzn, alpha_z, trial.n, mu, kappa)
            new.ep, new.en, new.xi = trial.p, trial.n, trial.xi
        if ev is None:
            new.ev = ph.evaluate(trial.x, y, z)
            if new.ev is None:
                raise Stop(
                    RIPMStatus.NUMERICAL_ERROR, "non-finite derivatives at the accepted point"
                )
        self.it = new
        accept = getattr(ph.problem, "accept", None)
        if accept is not None:
            accept(trial.x)
        self.sh.iter += 1
        tag = "r" if ph.resto else search.tag[0]
        self.last = StepRecord(alpha * amax(step.dx), dw, alpha_z, alpha, search.trials, tag)

    # ------------------------------------------------------------------ output
    def _record(self, objective: float, inf_pr: float | None = None) -> None:
        res = self.res
        inf_pr = res.inf_pr if inf_pr is None else inf_pr
        self.sh.recorder.record(self.sh.iter, objective, inf_pr, res, self.barrier.mu, self.last)

    def _result(self, status: RIPMStatus, message: str) -> RIPMResult:
        sh, it = self.sh, self.it
        if it.ev is not None and (self.res is None or not self.res.at(it)):
            self.res = self.phase.measures(it, self.barrier.mu)  # stopped after the iterate moved
        res = self.res if it.ev is not None else None
        counts = (sh.counters.n_eval, sh.counters.n_values, sh.kkt.n_factorizations)
        return sh.recorder.result(status, message, sh.iter, it, res, self.barrier.mu, counts)
