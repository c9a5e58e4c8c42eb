"""The per-process memo of the last few keys (patterns, analyses, plans)."""

import numpy as np
import pytest

from mbplan import memo
from mbplan.memo import RecentMemo
from mbplan.solvers import solve_ripm
from mbplan.solvers.kkt.reduced import reduction as reduction_module
from mbplan.tasks.speed import TASKS


def test_recent_memo_builds_once_and_drops_the_least_recently_used():
    memo: RecentMemo[list] = RecentMemo(2)
    built = []

    def build(key):
        built.append(key)
        return [key]

    a = memo.get_or_build("a", lambda: build("a"))
    assert memo.get_or_build("a", lambda: build("a")) is a and built == ["a"]
    memo.get_or_build("b", lambda: build("b"))
    memo.get("a")  # "a" now the most recent: "b" goes first
    memo.get_or_build("c", lambda: build("c"))
    assert len(memo) == 2 and memo.get("b") is None and memo.get("a") is a
    assert memo.get_or_build("b", lambda: build("b")) == ["b"] and built == ["a", "b", "c", "b"]
    memo.clear()
    assert len(memo) == 0 and memo.get("a") is None


def test_recent_memo_keeps_the_first_value_built_for_a_key_and_nothing_on_a_failed_build():
    memo: RecentMemo[list] = RecentMemo(4)
    first = memo.put("k", [1], replace=False)
    # a second build of the same key (another thread's, finishing later) yields the kept value
    assert memo.get_or_build("k", lambda: [2]) is first
    assert memo.put("k", [3], replace=False) is first
    assert memo.put("k", [4]) == [4] and memo.get("k") == [4]

    def failing() -> list:
        raise RuntimeError("build failed")

    with pytest.raises(RuntimeError, match="build failed"):
        memo.get_or_build("bad", failing)
    assert memo.get("bad") is None and len(memo) == 1


def test_recent_memo_gives_threads_building_one_key_the_same_value():
    import threading

    memo: RecentMemo[list] = RecentMemo(4)
    barrier = threading.Barrier(4, timeout=30)
    got: list[list] = []

    def build() -> list:
        barrier.wait()  # every thread misses, then builds its own value
        return [threading.get_ident()]

    threads = [
        threading.Thread(target=lambda: got.append(memo.get_or_build("k", build))) for _ in range(4)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert len(got) == 4 and all(g is got[0] for g in got)


def test_recent_memo_update_changes_the_kept_value_atomically():
    """``update``: the new value from the kept one (``None`` at first), the key most recent."""
    memo: RecentMemo[list] = RecentMemo(2)
    assert memo.update("a", lambda old: [1, *(old or [])]) == [1]
    assert memo.update("a", lambda old: [2, *(old or [])]) == [2, 1]
    memo.put("b", [0])
    memo.update("a", lambda old: old[:1])  # "a" now the most recent: "b" goes first
    memo.put("c", [3])
    assert memo.get("a") == [2] and memo.get("b") is None


def test_recent_memo_updates_from_threads_are_not_lost():
    """Each ``update`` reads and writes under the lock: 8 threads × 200 appends, none lost."""
    import threading

    memo: RecentMemo[list] = RecentMemo(2)

    def append(i: int) -> None:
        for _ in range(200):
            memo.update("k", lambda old: [*(old or []), i])

    threads = [threading.Thread(target=append, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert sorted(memo.get("k")) == sorted(i for i in range(8) for _ in range(200))


def test_clear_all_makes_a_solve_independent_of_the_solves_before_it():
    """The joint reduction picks its pivots on the first matrix of a pattern and keeps them for
    the process (iiwa with coal distances, case 0 after case 1: 37 instead of 33 iterations when
    this was written); after :func:`clear_all` every memo is empty and case 0 is solved bit for
    bit as in a process that solved nothing before it."""

    def solve(i):
        problem, x0, options = TASKS["iiwa-distance"](i)
        return solve_ripm(problem, x0, options)

    memo.clear_all()
    first = solve(0)
    memo.clear_all()
    solve(1)  # the memo now holds the pivots picked on case 1
    assert len(reduction_module._REDUCTIONS) > 0
    memo.clear_all()
    assert all(len(m) == 0 for m in list(memo._MEMOS))
    again = solve(0)
    assert again.iterations == first.iterations and again.objective == first.objective
    np.testing.assert_array_equal(again.y, first.y)
