"""``mbplan warmup``: compile and cache, once, the kernels and structures of the common plans
(:data:`mbplan.tasks.warmup.WARMUP_PLANS`), so that the first ``mbplan plan`` of a fresh
installation is as fast as the next ones."""

from __future__ import annotations

import argparse
import time

from mbplan.cli.support import names
from mbplan.errors import InputError


def _selected(only: tuple[str, ...] | None) -> list:
    from mbplan.tasks.warmup import WARMUP_PLANS

    known = {p.name: p for p in WARMUP_PLANS}
    unknown = [n for n in only or () if n not in known]
    if unknown:
        raise InputError(f"--only: unknown plan {unknown[0]!r}; choose from {', '.join(known)}")
    return [known[n] for n in only] if only else list(WARMUP_PLANS)


def _warmup(args: argparse.Namespace) -> int:
    plans = _selected(args.only)
    if args.list:
        for p in plans:
            print(
                f"{p.name:22s} mbplan.plan({p.task} OCP, {p.method!r}, warm_start={p.warm_start!r})"
            )
        return 0
    import numba
    from tqdm import tqdm

    from mbplan.engine.jit import cache_dir
    from mbplan.planning.solve import plan

    rows = []
    bar = tqdm(plans, desc="mbplan warmup", unit="plan")
    for p in bar:
        bar.set_postfix_str(p.name)
        start = time.perf_counter()
        result = plan(p.ocp(), p.method, warm_start=p.warm_start)
        rows.append((p.name, time.perf_counter() - start, result))
    bar.close()
    for name, wall, r in rows:
        print(
            f"{name:22s} {wall:6.1f} s: kernels {r.compile_time_s:5.1f} s, solve "
            f"{r.solve_time_s:5.2f} s ({r.status})"
        )
    numba_dir = numba.config.CACHE_DIR or "__pycache__ beside the sources"
    print(f"kernels and structures cached in {cache_dir()} (numba's: {numba_dir})")
    return 0


def add_warmup_parser(sub: argparse._SubParsersAction) -> None:
    """The ``warmup`` subcommand of the ``mbplan`` parser."""
    warmup = sub.add_parser(
        "warmup",
        help="compile and cache the kernels of the common plans once (a fresh installation's "
        "first plan then loads them instead of compiling for up to a minute)",
    )
    warmup.add_argument(
        "--only",
        type=names,
        default=None,
        metavar="NAMES",
        help="comma-separated plans to make (default: all; see --list)",
    )
    warmup.add_argument(
        "--list", action="store_true", help="list the plans (names and what they plan) and exit"
    )
    warmup.set_defaults(func=_warmup)
