"""Dock a quadrotor from a random pose with the RIPM on SO(3)×R³ and replay it in meshcat.

    python examples/drone_docking.py --seed 3 --out out/drone
prints the solver summary and writes ``docking.html`` (offline meshcat page).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import mbplan as mb
from mbplan.tasks import paper
from mbplan.tasks.drone import rotation_angles, sample_docking_cases
from mbplan.viz import drone_replay


def main(out: Path, seed: int, limits: bool) -> int:
    task = sample_docking_cases(1, seed, with_input_limits=limits)[0]
    angle = float(rotation_angles(task.R0[None])[0])
    r = mb.plan(paper.drone_docking(task), "ripm")
    check = mb.verify(r)  # replays the inputs through the NumPy LGVI
    R, p = r.R[:, 0], r.p[:, 0]
    print(
        f"start {np.round(task.p0, 2)} m, rotated {np.degrees(angle):.0f}°; input limits: {limits}"
    )
    print(
        f"RIPM: {r.status}, {r.iterations} iterations, {1e3 * r.solve_time_s:.1f} ms, KKT error {r.kkt_history[-1].max():.1e}"
    )
    print(
        f"final position error {np.linalg.norm(p[-1]):.3f} m; replay deviation {check.max_joint_deviation_rad:.1e}; verified: {check.passed}"
    )
    out.mkdir(parents=True, exist_ok=True)
    print(f"wrote {drone_replay(R, p, html=out / 'docking.html', dt=task.dt, open_browser=False)}")
    return 0 if r.success and check.passed else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("out/drone"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--limits", action="store_true", help="thrust and torque limits")
    a = parser.parse_args()
    raise SystemExit(main(a.out, a.seed, a.limits))
