"""A/B of the per-iteration profile: this tree against a baseline checkout, interleaved.

Each round runs the profile (``mbplan.benchmarks.kkt_profile.profile_solve``, ``--repeats``
solves per case, the minimum of each component) in a fresh process in the baseline tree and in
this tree, alternating which goes first; the report is, per task and component, the minimum over rounds per case and the
median over cases, with the iteration counts of both (they must agree). On a shared machine
only these side-by-side ratios mean anything.

    python benchmarks/ripm_profile_ab.py --baseline /work/main --tasks drone drone-limits \\
        --cases 3 --repeats 5 --rounds 4 --out benchmarks/results/overhead/drone.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mbplan.benchmarks.common import alternating_runs, median_of_min

KEYS = ("evaluate", "values", "retract", "assembly", "factorize", "solve", "python")

_CHILD = """
import json, sys
sys.path.insert(0, ".")
from mbplan.benchmarks.kkt_profile import profile_solve
from mbplan.tasks.speed import TASKS
tasks, cases, repeats = json.loads(sys.argv[1])
out = {}
for name in tasks:
    rows = []
    for i in range(cases):
        args = TASKS[name](i)
        runs = [profile_solve(*args) for _ in range(repeats)]
        row = {k: min(r[k] for r in runs) for k in runs[0] if k.endswith("_ms")}
        row["iterations"] = runs[0]["iterations"]
        rows.append(row)
    out[name] = rows
print(json.dumps(out))
"""


def summarize(runs: list[dict], task: str) -> dict:
    """Per component: min over rounds per case, median over cases (ms per iteration)."""
    out = median_of_min(runs, task, [f"{k}_ms" for k in KEYS])
    out.update({k: out.pop(f"{k}_ms") for k in KEYS})
    out["sum"] = sum(out[k] for k in KEYS)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", required=True, help="root of the baseline checkout")
    ap.add_argument("--tasks", nargs="+", default=["drone", "drone-limits"])
    ap.add_argument("--cases", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    trees = {"baseline": Path(args.baseline), "new": Path(__file__).resolve().parents[1]}
    runs = alternating_runs(trees, _CHILD, [args.tasks, args.cases, args.repeats], args.rounds)
    report = {}
    for task in args.tasks:
        report[task] = {tag: summarize(r, task) for tag, r in runs.items()}
        b, n = report[task]["baseline"], report[task]["new"]
        print(f"{task}: iterations {b['iterations']} / {n['iterations']}")
        for k in (*KEYS, "sum"):
            print(f"  {k:10s} {b[k]:8.3f} -> {n[k]:8.3f} ms/iter ({n[k] / b[k]:.2f}x)")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps({"report": report, "runs": runs}, indent=1))


if __name__ == "__main__":
    main()
