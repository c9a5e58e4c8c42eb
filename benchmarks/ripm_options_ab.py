"""Opt-in RIPM options against the defaults, interleaved in one process on the profile tasks.

Each (task, case) is solved with every variant in turn (``profile_solve``: a warm-up solve,
then a timed one); prints one JSON line per solve (iterations, ms per iteration, factorize and
solve ms per iteration). ``base`` is ``RIPMOptions()`` of the checkout, ``s6`` the defaults
before session 7 (monotone μ, full KKT); the others override ``base``.

    python benchmarks/ripm_options_ab.py --tasks iiwa-com --cases 3 --variants base red bar red+bar
    python benchmarks/ripm_options_ab.py --tasks chain4 chain16 chain64 --cases 1 --variants base red piv all
    python benchmarks/ripm_options_ab.py --tasks iiwa-com --variants base red --eps 1e-9 1e-10 1e-11
    python benchmarks/ripm_options_ab.py --tasks chain4 chain8 chain16 chain32 chain64 --cases 1 --variants base s6
    python benchmarks/ripm_options_ab.py --tasks drone drone-limits --cases 100 --variants base deg0
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.kkt_profile import profile_solve
from mbplan.tasks.speed import TASKS

REDUCED = {"kkt_method": "auto"}
PIVOTED_METIS = {"kkt_ordering": "auto", "kkt_pivot_threshold": 1e-10}
MEHROTRA = {
    "mu_strategy": "adaptive",
    "mu_oracle": "probing",
    "mu_max_fact": 0.0,
    "corrector": True,
}
SESSION6 = {
    "mu_strategy": "monotone",
    "mu_oracle": "loqo",
    "mu_max_fact": 1e3,
    "corrector": False,
    "kkt_method": "full",
}
VARIANTS = {
    "base": {},
    "s6": SESSION6,
    "red": REDUCED,
    "piv": PIVOTED_METIS,
    "bar": MEHROTRA,
    "red+bar": REDUCED | MEHROTRA,
    "all": REDUCED | PIVOTED_METIS | MEHROTRA,
    "deg0": {"degenerate_iters": 0},
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", nargs="+", default=["iiwa-com"], choices=list(TASKS))
    ap.add_argument("--cases", type=int, default=3)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--eps", nargs="+", type=float, default=[None], help="static_regularization")
    args = ap.parse_args()
    for task in args.tasks:
        for case in range(args.cases):
            problem, x0, options = TASKS[task](case)
            for eps, name in ((e, v) for e in args.eps for v in args.variants):
                chosen = VARIANTS[name] | ({} if eps is None else {"static_regularization": eps})
                r = profile_solve(problem, x0, dataclasses.replace(options, **chosen))
                row = {"task": task, "case": case, "variant": name, "status": r["status"]}
                row |= {"static_regularization": chosen.get("static_regularization")}
                row |= {"iterations": r["iterations"], "ms_per_iter": round(r["per_iter_ms"], 2)}
                row |= {"factorize_ms": round(r["factorize_ms"], 2)}
                row |= {"solve_ms": round(r["solve_ms"], 2), "total_ms": round(r["total_ms"], 1)}
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
