"""Replay one RIPM solve's KKT calls through the reduced step: this tree against a baseline
checkout, interleaved, per method of the reduction.

``record`` solves a task's case with the default options and stores every call to the reduced
system (``set_matrices``' matrices, ``factorize``' diagonals, ``solve``'s right-hand sides, in
order) and the elimination plan in a pickle. Each round then replays the calls in a fresh
process of the baseline tree and of this tree (alternating which goes first), ``--repeats``
times per process (after a warm-up pass), with timers on the reduced system's entry points and
on the :class:`~mbplan.solvers.reduction.Reduction` methods (exclusive times, a timer's own
~1 µs included). Report: per timer, the minimum over repeats and rounds, ms per iteration of
the recorded solve; and whether the two trees' inertias and steps agree.

    python benchmarks/reduction_replay.py --baseline /work/base --task iiwa-com --case 0 \\
        --rounds 3 --repeats 5 --out benchmarks/results/redk/replay.json
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.common import run_in_tree

_CHILD = r"""
import json, pickle, sys, time
from collections import defaultdict
import numpy as np
sys.path.insert(0, ".")
from mbplan.solvers import reduction as R
from mbplan.solvers.elimination import EliminationPlan
from mbplan.solvers.linear_solver import KKTSystem
from mbplan.solvers.reduced_step import ReducedKKTSystem
path, repeats, tag = json.loads(sys.argv[1])
rec = pickle.load(open(path, "rb"))
plan = EliminationPlan(**rec["plan"])
clock, inner = defaultdict(float), []

def wrap(cls, name, label):
    fn = getattr(cls, name)
    def timed(*a, **kw):
        t0 = time.perf_counter()
        inner.append(0.0)
        try:
            return fn(*a, **kw)
        finally:
            dt = time.perf_counter() - t0
            clock[label] += dt - inner.pop()
            if inner:
                inner[-1] += dt
    setattr(cls, name, timed)

for name in ("set_values", "factorize", "solve_once", "matvec", "_add_lower", "_product"):
    if hasattr(R.Reduction, name):
        wrap(R.Reduction, name, "Reduction." + name)
for name in ("set_matrices", "factorize", "solve", "matvec"):
    wrap(ReducedKKTSystem, name, "ReducedKKTSystem." + name)
    wrap(KKTSystem, name, "KKTSystem." + name)

def replay():
    kkt = ReducedKKTSystem(*rec["dims"], lambda ae: plan)
    out = []
    for call, args in rec["calls"]:
        r = getattr(kkt, call)(*args)
        if call == "factorize":
            out.append(None if r is None else [r.positive, r.negative, r.zero])
        elif call == "solve":
            out.append(r[0])
    return out, kkt.n_reduced, kkt.n_fallbacks

replay()
best = None
for _ in range(repeats):
    clock.clear()
    out, nred, nfb = replay()
    best = dict(clock) if best is None else {k: min(v, clock[k]) for k, v in best.items()}
steps = [o for o in out if isinstance(o, np.ndarray)]
inertias = [o for o in out if not isinstance(o, np.ndarray)]
np.save(path + "." + tag + ".npy", np.concatenate(steps))
print(json.dumps({"ms": {k: 1e3 * v for k, v in best.items()}, "inertias": inertias,
                  "reduced": nred, "fallbacks": nfb}))
"""


def record(task: str, case: int, path: Path) -> None:
    """Solve ``task``'s case with the default options, store its reduced-system calls."""
    from mbplan.solvers.linear_solver import _csr
    from mbplan.solvers.reduced_step import ReducedKKTSystem

    from mbplan.solvers import solve_ripm
    from mbplan.tasks.speed import TASKS

    def same_pattern(a, b):
        return np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)

    problem, x0, opts = TASKS[task](case)
    calls = []
    saved = {m: getattr(ReducedKKTSystem, m) for m in ("set_matrices", "factorize", "solve")}

    def copy(a):
        return a.copy() if hasattr(a, "copy") else a

    def spy(name):
        def call(self, *args):
            calls.append((name, tuple(copy(a) for a in args)))
            return saved[name](self, *args)

        return call

    try:
        for m in saved:
            setattr(ReducedKKTSystem, m, spy(m))
        res = solve_ripm(problem, x0, opts)
    finally:
        for m, fn in saved.items():
            setattr(ReducedKKTSystem, m, fn)
    jacs = [_csr(a[1], (problem.n_eq, problem.n)) for c, a in calls if c == "set_matrices"]
    if any(not same_pattern(j, jacs[0]) for j in jacs):
        raise SystemExit("the replay needs one pattern of A_E")
    plan = problem.elimination_plan(jacs[0])
    rec = {
        "dims": (int(problem.n), int(problem.n_eq), int(problem.n_ineq)),
        "plan": {f: getattr(plan, f) for f in plan.__dataclass_fields__},
        "calls": calls,
        "iterations": res.iterations,
    }
    path.write_bytes(pickle.dumps(rec))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", type=Path, required=True)
    ap.add_argument("--task", default="iiwa-com")
    ap.add_argument("--case", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    here = Path(__file__).resolve().parents[1]
    path = Path(tempfile.gettempdir()) / f"reduction-replay-{args.task}-{args.case}.pkl"
    record(args.task, args.case, path)
    iterations = pickle.loads(path.read_bytes())["iterations"]
    trees = {"base": args.baseline.resolve(), "tree": here}
    runs: dict[str, list[dict]] = {k: [] for k in trees}
    for r in range(args.rounds):
        order = list(trees) if r % 2 == 0 else list(trees)[::-1]
        for k in order:
            runs[k].append(run_in_tree(trees[k], _CHILD, [str(path), args.repeats, k]))
    steps = [np.load(f"{path}.{k}.npy") for k in trees]
    ms = {
        k: {t: min(run["ms"][t] / iterations for run in v) for t in v[0]["ms"]}
        for k, v in runs.items()
    }
    out = {
        "task": args.task,
        "case": args.case,
        "iterations": iterations,
        "ms_per_iteration": ms,
        "same_inertias": runs["base"][0]["inertias"] == runs["tree"][0]["inertias"],
        "step_rel_diff": float(np.abs(steps[0] - steps[1]).max() / np.abs(steps[0]).max()),
        "reduced_fallbacks": {k: (v[0]["reduced"], v[0]["fallbacks"]) for k, v in runs.items()},
    }
    print(f"{'timer':40s} {'base':>8s} {'tree':>8s} {'ratio':>6s}")
    for t in sorted(ms["base"], key=lambda t: -ms["base"][t]):
        a, b = ms["base"][t], ms["tree"].get(t, np.nan)
        print(f"{t:40s} {a:8.3f} {b:8.3f} {b / a:6.2f}")
    tot = {k: sum(v.values()) for k, v in ms.items()}
    print(f"{'total':40s} {tot['base']:8.3f} {tot['tree']:8.3f} {tot['tree'] / tot['base']:6.2f}")
    print(
        "same inertias:",
        out["same_inertias"],
        "steps' relative difference:",
        out["step_rel_diff"],
        "reduced, fallbacks:",
        out["reduced_fallbacks"],
    )
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
