"""The result store of a benchmark run: one ``--out`` folder, one configuration, one writer.

``results.jsonl`` holds one JSON row per finished (case, method) job, each tagged with the hash
of the run's configuration (:func:`config_hash`: everything that changes a row — task, seed,
warm start, constraint, tolerances, method options — and the mbplan version).
``results.config.json`` beside it records that configuration. A run into a folder holding rows
of another configuration is refused with the fields that differ (choose another ``--out``, or
delete the folder); rows are resumed by (configuration, case, method). An ``flock`` on the folder (released by the kernel when
its process dies, even by SIGKILL) keeps a second run from writing the same folder.

Every row is one ``write`` of a complete line to a file opened in append mode, flushed and
fsynced, so an interrupted run loses at most the jobs still running. :func:`repair` keeps every
valid line of a damaged file (a line cut by a kill, a corrupt line in the middle, a duplicate),
moves the others to ``results.jsonl.rejected`` and says which lines it moved.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from mbplan.benchmarks.common import write_atomic, write_json
from mbplan.errors import InputError


def config_hash(config: Mapping[str, Any]) -> str:
    """Short SHA-256 of ``config`` (canonical JSON) and the mbplan version."""
    from mbplan import __version__

    text = json.dumps({"config": dict(config), "mbplan": __version__}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@contextlib.contextmanager
def locked(results: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on the folder of ``results`` for the block (no lock file is
    left; the kernel releases it when the process dies); :class:`InputError` if another process
    holds it."""
    import fcntl

    fd = os.open(results.parent, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            if err.errno not in (errno.EAGAIN, errno.EACCES):
                raise
            raise InputError(
                f"{results.parent}: another benchmark run is writing there; wait for it or "
                "choose another --out"
            ) from None
        yield
    finally:
        os.close(fd)  # releases the lock


def check_config(results: Path, config: Mapping[str, Any]) -> str:
    """Record ``config`` beside ``results`` (``results.config.json``) or check it equals the
    recorded one; return its hash. :class:`InputError` naming the differing fields if the rows
    were made with another configuration (or without a recorded one)."""
    key = config_hash(config)
    path = config_path(results)
    if not results.exists() or results.stat().st_size == 0:
        write_json(path, {"hash": key, "config": dict(config)})  # no rows yet: nothing to mix
        return key
    if not path.exists():
        raise InputError(
            f"{results} holds results without a recorded configuration ({path.name}, older "
            "mbplan?): they cannot be resumed safely; choose another --out or delete them"
        )
    try:
        old = json.loads(path.read_text())
        old_key, old_config = old["hash"], old["config"]
    except (ValueError, KeyError, TypeError):
        raise InputError(f"{path}: not a benchmark configuration record; delete it") from None
    if old_key != key:
        changed = sorted(set(old_config) | set(config))
        shown = lambda c, k: repr(c[k]) if k in c else "(unset)"  # noqa: E731
        diff = [
            f"{k} {shown(old_config, k)} -> {shown(config, k)}"
            for k in changed
            if old_config.get(k) != config.get(k)
        ] or ["the mbplan version"]
        raise InputError(
            f"{results.parent} holds results of another configuration ({'; '.join(diff)}); "
            "choose another --out or delete it"
        )
    return key


def config_path(results: Path) -> Path:
    """Where the configuration of ``results`` (``NAME.jsonl``) is recorded: ``NAME.config.json``."""
    return results.with_suffix(".config.json")


def repair(results: Path, key: str) -> list[dict]:
    """The valid rows of ``results`` (JSON objects with ``case``, ``method`` and ``config ==
    key``, first of each (case, method)); any other non-empty line is moved to
    ``results.rejected`` with a warning naming its line number, the valid ones are kept in
    order."""
    if not results.exists():
        return []
    lines = results.read_text().split("\n")
    rows: list[dict] = []
    kept: list[str] = []
    rejected: list[tuple[int, str, str]] = []
    seen: set[tuple[int, str]] = set()
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        why = None
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            why = "not valid JSON (cut by a kill?)"
        else:
            if not isinstance(row, dict) or not {"case", "method"} <= row.keys():
                why = "not a result row"
            elif row.get("config") != key:
                why = f"configuration {row.get('config')!r}, not {key!r}"
            elif (row["case"], row["method"]) in seen:
                why = f"duplicate of case {row['case']}, method {row['method']!r}"
        if why is not None:
            rejected.append((number, why, line))
            continue
        seen.add((row["case"], row["method"]))
        rows.append(row)
        kept.append(line)
    trailing_cut = not results.read_bytes().endswith(b"\n") and bool(lines[-1].strip())
    if rejected or trailing_cut:
        if rejected:
            side = results.with_name(results.name + ".rejected")
            with side.open("a") as fh:
                fh.writelines(f"{line}\n" for _, _, line in rejected)
            warnings.warn(
                f"{results}: moved {len(rejected)} bad line(s) to {side.name}, kept "
                f"{len(kept)} valid row(s): "
                + "; ".join(f"line {n}: {why}" for n, why, _ in rejected),
                stacklevel=2,
            )
        write_atomic(results, "".join(f"{line}\n" for line in kept))
    return rows


class Appender:
    """Appends complete rows to a results file (one ``write`` per line, fsynced)."""

    def __init__(self, results: Path) -> None:
        self._fd = os.open(results, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    def append(self, row: Mapping[str, Any]) -> None:
        data = (json.dumps(row) + "\n").encode()
        written = os.write(self._fd, data)
        if written != len(data):  # a full disk: never leave a cut line behind silently
            raise OSError(errno.ENOSPC, f"short write ({written} of {len(data)} bytes)")
        os.fsync(self._fd)

    def close(self) -> None:
        os.close(self._fd)
