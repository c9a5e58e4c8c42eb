"""Where a RIPM iteration spends its time: per-iteration breakdown on the benchmark tasks.

Wraps the problem (``evaluate``/``values``/``retract``) and ``KKTSystem`` (``set_matrices``,
``factorize``, ``solve``) with timers; the rest of the wall time is the solver's own Python.

    python benchmarks/ripm_profile.py [--cases 3] [--out benchmarks/results/speed/profile-before.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.kkt_profile import profile_solve
from mbplan.tasks.speed import TASKS


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=3)
    ap.add_argument("--tasks", nargs="*", default=list(TASKS))
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    rows = {}
    for name in args.tasks:
        rows[name] = [profile_solve(*TASKS[name](i)) for i in range(args.cases)]
        for r in rows[name]:
            print(
                name,
                json.dumps({k: (round(v, 5) if isinstance(v, float) else v) for k, v in r.items()}),
            )
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
