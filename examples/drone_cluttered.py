"""Drone docking through a cluttered environment (RIPM paper Fig. 5).

The RIPM plans on SO(3)×R³ with input limits and three cylinders ``(x-x_c)² + (y-y_c)² ≥ r²``;
the path is plotted from above with the cylinders and the body z axis along the way.

    python examples/drone_cluttered.py --out docs/drone_cluttered.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import mbplan as mb
from mbplan.tasks import paper
from mbplan.tasks.drone import cluttered_task


def main(out: Path, tol: float = 1e-8) -> int:
    task = cluttered_task(with_input_limits=True)
    r = mb.plan(paper.drone_docking(task), "ripm", tol=tol, max_iter=200)
    check = mb.verify(r)  # replays the inputs through the NumPy LGVI
    print(f"RIPM: {r.status} in {r.iterations} iterations, {1e3 * r.solve_time_s:.1f} ms")
    print(f"replay deviation through the LGVI simulator: {check.max_joint_deviation_rad:.2e}")
    p, R = r.p[:, 0], r.R[:, 0]
    clearance = min(
        np.hypot(p[1:, 0] - x, p[1:, 1] - y).min() - rad for x, y, rad in task.obstacles
    )
    print(f"min clearance to the cylinders at the knots: {clearance:.4f} m")

    fig, ax = plt.subplots(figsize=(6, 5))
    for x, y, rad in task.obstacles:
        ax.add_patch(plt.Circle((x, y), rad, color="0.6"))
    ax.plot(p[:, 0], p[:, 1], "o-", ms=3, label="RIPM path (knots)")
    z = R[:, :, 2]  # body z axis (thrust direction)
    ax.quiver(
        p[::4, 0],
        p[::4, 1],
        z[::4, 0],
        z[::4, 1],
        angles="xy",
        scale=8,
        width=0.004,
        label="body z",
    )
    ax.plot(*task.p0[:2], "ks", label="start")
    ax.plot(0, 0, "r*", ms=12, label="goal")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"Drone through clutter: {r.status}, {r.iterations} iterations")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")
    return 0 if r.success and clearance >= -1e-6 else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("out/drone_cluttered.png"))
    raise SystemExit(main(parser.parse_args().out))
