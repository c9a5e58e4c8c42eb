"""The per-process memo of the last few keys (patterns, analyses, plans)."""

from mbplan.memo import RecentMemo


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
