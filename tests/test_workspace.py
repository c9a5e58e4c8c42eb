"""The caller's workspace: what the solves of one problem family share, built once per key."""

import pickle
import threading

import numpy as np
import pytest

from mbplan.solvers import solve_ripm
from mbplan.solvers.kkt.reduced import reduction as reduction_module
from mbplan.tasks.speed import TASKS
from mbplan.workspace import Workspace, shared


def test_workspace_builds_once_per_kind_and_key_and_drops_the_least_recently_used():
    ws = Workspace(kept=2)
    built = []

    def build(key):
        built.append(key)
        return [key]

    a = ws.get_or_build("x", "a", lambda: build("a"))
    assert ws.get_or_build("x", "a", lambda: build("a")) is a and built == ["a"]
    assert ws.get_or_build("y", "a", lambda: build("a")) is not a  # kinds are separate
    ws.get_or_build("x", "b", lambda: build("b"))
    ws.get_or_build("x", "a", lambda: build("a"))  # "a" now the most recent: "b" goes first
    ws.get_or_build("x", "c", lambda: build("c"))
    assert ws.count("x") == 2 and ws.count("y") == 1 and ws.count("z") == 0
    assert ws.get_or_build("x", "a", lambda: build("a")) is a
    ws.get_or_build("x", "b", lambda: build("b"))
    assert built == ["a", "a", "b", "c", "b"]


def test_shared_without_a_workspace_builds_every_time_and_a_failed_build_keeps_nothing():
    assert shared(None, "x", lambda: 1 / 0, lambda: [1]) == [1]  # no key computed
    ws = Workspace()

    def failing() -> list:
        raise RuntimeError("build failed")

    with pytest.raises(RuntimeError, match="build failed"):
        shared(ws, "x", lambda: "k", failing)
    assert ws.count("x") == 0
    assert shared(ws, "x", lambda: "k", lambda: [2]) == [2] and ws.count("x") == 1


def test_threads_building_one_key_get_the_same_value():
    ws = Workspace()
    barrier = threading.Barrier(4, timeout=30)
    got: list[list] = []

    def build() -> list:
        barrier.wait()  # every thread misses, then builds its own value
        return [threading.get_ident()]

    threads = [
        threading.Thread(target=lambda: got.append(ws.get_or_build("x", "k", build)))
        for _ in range(4)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert len(got) == 4 and all(g is got[0] for g in got)


def test_a_reused_workspace_builds_nothing_again_and_changes_no_result(monkeypatch):
    """A problem solved again with the same workspace reuses its KKT pattern, analysis and
    reduction (the same values: the same pick) and gives the result of a solve with none (the
    disk cache off: every entry is built here)."""
    monkeypatch.setenv("MBPLAN_DISK_CACHE", "off")
    built = []
    original = reduction_module.Reduction.__init__

    def counted(self, *args, **kwargs) -> None:
        built.append(1)
        original(self, *args, **kwargs)

    monkeypatch.setattr(reduction_module.Reduction, "__init__", counted)
    problem, x0, options = TASKS["chain4"](0)
    alone = solve_ripm(problem, x0, options)
    assert len(built) == 1
    ws = Workspace()
    first = solve_ripm(problem, x0, options, workspace=ws)
    kept = {k: ws.count(k) for k in ("kkt_pattern", "analysis", "reduction")}
    assert all(kept.values()) and len(built) == 2
    again = solve_ripm(problem, x0, options, workspace=ws)
    assert len(built) == 2 and {k: ws.count(k) for k in kept} == kept
    for result in (first, again):
        assert result.iterations == alone.iterations and result.objective == alone.objective
        np.testing.assert_array_equal(result.y, alone.y)


def test_a_workspace_sent_to_another_process_arrives_empty_and_usable():
    """Benchmark jobs carry their family's workspace; a worker process gets an empty one with
    the same capacity, which builds its entries again (the same values)."""
    ws = Workspace(kept=3)
    ws.get_or_build("kind", "key", lambda: 1)
    copy = pickle.loads(pickle.dumps(ws))
    assert copy.kept == 3 and copy.count("kind") == 0
    assert copy.get_or_build("kind", "key", lambda: 1) == 1 and copy.count("kind") == 1
    assert ws.count("kind") == 1
