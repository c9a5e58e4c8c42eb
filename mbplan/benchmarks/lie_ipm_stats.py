"""The MLG-IPM paper's statistics (§V) with ``scipy.stats``.

* Lilliefors: the Kolmogorov-Smirnov statistic against a normal with estimated mean and variance,
  its null distribution by Monte Carlo (``scipy.stats.goodness_of_fit``, which is Lilliefors'
  construction; statsmodels is not a dependency);
* Wilcoxon-Mann-Whitney (``mannwhitneyu``, two-sided) on times, iterations and errors;
* χ² on the 2×2 success table without continuity correction (``chi2_contingency``), whose
  survival function is the p-value (the paper's "p = 1" is its CDF), and Cramér's V = √(χ²/N);
* the pooled two-proportion Z test; Cohen's d with the pooled standard deviation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.stats

SUMMARY_KEYS = (
    "n",
    "success",
    "median_iters",
    "mean_iters",
    "median_time_s",
    "mean_time_s",
    "error_mean",
)


def _f(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def describe(rows: Sequence[dict]) -> dict:
    """Per-method statistics: iterations and times over all runs, error over successful runs."""
    its = np.array([r["iterations"] for r in rows], dtype=float)
    times = np.array([r["time_s"] for r in rows], dtype=float)
    errs = np.array([r["error"] for r in rows if r["success"]], dtype=float)

    def stat(fn, a):
        return _f(fn(a)) if a.size else None

    return {
        "n": len(rows),
        "success": int(sum(bool(r["success"]) for r in rows)),
        "median_iters": stat(np.median, its),
        "mean_iters": stat(np.mean, its),
        "median_time_s": stat(np.median, times),
        "mean_time_s": stat(np.mean, times),
        "error_mean": stat(np.mean, errs),
        "sd_iters": stat(np.std, its),
        "sd_time_s": stat(np.std, times),
        "error_sd": stat(np.std, errs),
    }


def lilliefors_p(x: Sequence[float], n_mc: int = 999, seed: int = 0) -> float | None:
    """Lilliefors' test of normality (Monte Carlo p-value)."""
    a = np.asarray(x, dtype=float)
    if a.size < 4 or np.ptp(a) == 0:
        return None
    res = scipy.stats.goodness_of_fit(
        scipy.stats.norm, a, statistic="ks", n_mc_samples=n_mc, rng=np.random.default_rng(seed)
    )
    return float(res.pvalue)


def proportions(s1: int, n1: int, s2: int, n2: int) -> dict:
    """χ² (no correction), its p-value, Cramér's V and the pooled two-proportion Z test."""
    table = np.array([[s1, n1 - s1], [s2, n2 - s2]], dtype=float)
    if np.any(table.sum(axis=0) == 0):
        return {"chi2": 0.0, "chi2_p": 1.0, "cramers_v": 0.0, "z": 0.0, "z_p": 1.0}
    chi2, p, _, _ = scipy.stats.chi2_contingency(table, correction=False)
    pooled = (s1 + s2) / (n1 + n2)
    z = (s1 / n1 - s2 / n2) / np.sqrt(pooled * (1 - pooled) * (1 / n1 + 1 / n2))
    return {
        "chi2": float(chi2),
        "chi2_p": float(p),
        "cramers_v": float(np.sqrt(chi2 / table.sum())),
        "z": float(z),
        "z_p": float(2 * scipy.stats.norm.sf(abs(z))),
    }


def cohens_d(a: Sequence[float], b: Sequence[float]) -> float | None:
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.size < 2 or y.size < 2:
        return None
    pooled = np.sqrt(
        ((x.size - 1) * x.var(ddof=1) + (y.size - 1) * y.var(ddof=1)) / (x.size + y.size - 2)
    )
    return _f((x.mean() - y.mean()) / pooled) if pooled > 0 else None


def _wmw(a: Sequence[float], b: Sequence[float]) -> float | None:
    if len(a) < 1 or len(b) < 1:
        return None
    return _f(scipy.stats.mannwhitneyu(a, b, alternative="two-sided").pvalue)


def compare(rows_a: Sequence[dict], rows_b: Sequence[dict]) -> dict:
    """The paper's tests of method A (MLG-IPM) against method B on the same instances."""
    sa = sum(bool(r["success"]) for r in rows_a)
    sb = sum(bool(r["success"]) for r in rows_b)
    out = proportions(sa, len(rows_a), sb, len(rows_b))
    ta, tb = ([r["time_s"] for r in rs] for rs in (rows_a, rows_b))
    ia, ib = ([r["iterations"] for r in rs] for rs in (rows_a, rows_b))
    ea = [r["error"] for r in rows_a if r["success"]]
    eb = [r["error"] for r in rows_b if r["success"]]
    out |= {
        "lilliefors_p_time": [lilliefors_p(ta), lilliefors_p(tb)],
        "lilliefors_p_iters": [lilliefors_p(ia), lilliefors_p(ib)],
        "wmw_p_time": _wmw(ta, tb),
        "wmw_p_iters": _wmw(ia, ib),
        "wmw_p_error": _wmw(ea, eb),
        "cohens_d_time": cohens_d(ta, tb),
        "cohens_d_iters": cohens_d(ia, ib),
        "median_time_difference_s": _f(np.median(tb) - np.median(ta)) if ta and tb else None,
        "median_iters_difference": _f(np.median(ib) - np.median(ia)) if ia and ib else None,
    }
    return out
