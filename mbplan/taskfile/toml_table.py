"""Reading a hand-written TOML file with errors that name the key and its line.

:func:`read_toml` parses the file (``tomllib``) and applies command-line overrides; a
:class:`Table` reads one table of it with typed getters that raise
:class:`~mbplan.errors.InputError` as ``FILE:LINE: [table].key: what is wrong``. ``tomllib``
keeps no positions, so :func:`key_lines` finds them by scanning the text for table headers and
``key =`` lines (enough for hand-written files; a key it cannot place is named without a line).
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from mbplan.errors import InputError

Key = tuple[str | int, ...]  # a path into the document: table names, array indices, the key

_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-\" ]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-]+|\"[^\"]*\")\s*=")
_INLINE_KEY = re.compile(r"[{,]\s*([A-Za-z0-9_\-]+|\"[^\"]*\")\s*=")


def key_lines(text: str) -> dict[Key, int]:
    """Line (1-based) of every table header and ``key =`` of ``text``; keys of one-line inline
    tables (``lock = { a = 1 }``) get the line of their table."""
    lines: dict[Key, int] = {}
    table: Key = ()
    counts: dict[Key, int] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        header = _HEADER.match(line)
        if header:
            path: Key = tuple(p.strip().strip('"') for p in header.group(2).split("."))
            if header.group(1) == "[[":
                index = counts.get(path, 0)
                counts[path] = index + 1
                path = (*path, index)
            table = path
            lines.setdefault(table, number)
            continue
        key = _KEY.match(line)
        if key:
            name = key.group(1).strip('"')
            lines.setdefault((*table, name), number)
            for inner in _INLINE_KEY.finditer(line[key.end() :]):
                lines.setdefault((*table, name, inner.group(1).strip('"')), number)
    return lines


def label(key: Key) -> str:
    """``[goal].xyz``, ``[[obstacle]]#2.size``, ``[robot].lock.joint1``."""
    if not key:
        return "the file"
    head, rest = key[0], list(key[1:])
    out = f"[{head}]"
    if rest and isinstance(rest[0], int):
        out = f"[[{head}]]#{rest.pop(0) + 1}"
    for part in rest:
        out += f"#{part + 1}" if isinstance(part, int) else f".{part}"
    return out


class Document:
    """A parsed TOML file: its data, where each key is, and which keys an override set."""

    def __init__(self, path: Path, data: dict[str, Any], text: str, overridden: Mapping) -> None:
        self.path, self.data, self.text = path, data, text
        self.lines = key_lines(text)
        self.overridden: dict[Key, str] = dict(overridden)

    def where(self, key: Key) -> str:
        """``FILE:LINE: [table].key`` (``FILE: [table].key (from --flag)`` if overridden)."""
        origin = [o for k, o in self.overridden.items() if k[: len(key)] == key]
        if origin:
            return f"{self.path}: {label(key)} (from {origin[0]})"
        for n in range(len(key), 0, -1):
            if key[:n] in self.lines:
                return f"{self.path}:{self.lines[key[:n]]}: {label(key)}"
        return f"{self.path}: {label(key)}"

    def error(self, key: Key, message: str) -> InputError:
        return InputError(f"{self.where(key)}: {message}")

    def table(self, name: str, *, required: bool = False, what: str = "") -> Table:
        value = self.data.get(name)
        if value is None:
            if required:
                raise InputError(f"{self.path}: missing table [{name}]{what}")
            return Table(self, (name,), {})
        if not isinstance(value, dict):
            raise self.error((name,), f"expected a table, got {_kind(value)}")
        return Table(self, (name,), value)

    def tables(self, name: str) -> list[Table]:
        """The tables of an array of tables ``[[name]]`` (none if absent)."""
        value = self.data.get(name, [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error((name,), f"expected [[{name}]] tables, got {_kind(value)}")
        return [Table(self, (name, i), v) for i, v in enumerate(value)]

    def check_tables(self, known: Iterable[str]) -> None:
        known = list(known)
        for name in self.data:
            if name not in known:
                raise self.error((name,), f"unknown table; known: {', '.join(known)}")


class Table:
    """One table of a :class:`Document`; getters name ``[table].key`` (and its line) on error."""

    def __init__(self, doc: Document, key: Key, data: dict[str, Any]) -> None:
        self.doc, self.key, self.data = doc, key, data

    def __contains__(self, name: str) -> bool:
        return name in self.data

    def error(self, name: str | None, message: str) -> InputError:
        return self.doc.error(self.key if name is None else (*self.key, name), message)

    def check_keys(self, known: Sequence[str]) -> None:
        """Refuse keys not in ``known`` (a typo would silently do nothing)."""
        for name in self.data:
            if name not in known:
                raise self.error(name, f"unknown key; known: {', '.join(known)}")

    def _get(self, name: str, required: bool, hint: str) -> Any:
        if name not in self.data:
            if required:
                raise self.error(None, f"missing key {name!r}{hint}")
            return None
        return self.data[name]

    def string(
        self, name: str, *, required: bool = False, choices: Sequence[str] = (), hint: str = ""
    ) -> str | None:
        value = self._get(name, required, hint)
        if value is None:
            return None
        if not isinstance(value, str) or not value:
            raise self.error(name, f"expected a non-empty string, got {_kind(value)}")
        if choices and value not in choices:
            raise self.error(name, f"{value!r} is not one of {', '.join(choices)}")
        return value

    def number(
        self, name: str, *, required: bool = False, positive: bool = False, minimum: float = 0.0
    ) -> float | None:
        """A finite number ``>= minimum`` (``> 0`` if ``positive``); integers are accepted."""
        value = self._get(name, required, "")
        if value is None:
            return None
        return _number(value, lambda m: self.error(name, m), positive, minimum)

    def integer(self, name: str, *, required: bool = False, minimum: int = 0) -> int | None:
        value = self._get(name, required, "")
        if value is None:
            return None
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.error(name, f"expected an integer, got {_kind(value)}")
        if value < minimum:
            raise self.error(name, f"must be an integer >= {minimum}, got {value}")
        return value

    def boolean(self, name: str, default: bool) -> bool:
        value = self.data.get(name, default)
        if not isinstance(value, bool):
            raise self.error(name, f"expected true or false, got {_kind(value)}")
        return value

    def vector(
        self,
        name: str,
        size: int | Sequence[int] | None,
        *,
        required: bool = False,
        positive: bool = False,
        hint: str = "",
    ) -> list[float] | None:
        """A list of finite numbers of length ``size`` (one of them if a sequence; any if None)."""
        value = self._get(name, required, hint)
        if value is None:
            return None
        if not isinstance(value, list):
            raise self.error(name, f"expected a list of numbers, got {_kind(value)}{hint}")
        sizes = (size,) if isinstance(size, int) else size
        if sizes is not None and len(value) not in sizes:
            want = " or ".join(str(s) for s in sizes)
            raise self.error(name, f"expected {want} numbers, got {len(value)}{hint}")
        return [
            _number(v, lambda m, i=i: self.error(name, f"item {i + 1}: {m}"), positive, -math.inf)
            for i, v in enumerate(value)
        ]

    def strings(self, name: str) -> list[str] | None:
        value = self.data.get(name)
        if value is None:
            return None
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise self.error(name, f"expected a list of strings, got {_kind(value)}")
        return value


def _number(value: Any, error, positive: bool, minimum: float) -> float:
    if not isinstance(value, int | float) or isinstance(value, bool):
        raise error(f"expected a number, got {_kind(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise error(f"must be a finite number, got {value}")
    if positive and x <= 0.0:
        raise error(f"must be > 0, got {value}")
    if x < minimum:
        raise error(f"must be >= {minimum:g}, got {value}")
    return x


def _kind(value: Any) -> str:
    if isinstance(value, str):
        return f"the string {value!r}"
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    return f"{type(value).__name__} {value!r}"


def parse_value(text: str, flag: str) -> Any:
    """A TOML value given on the command line (``--set robot.lock='["j1"]'``); a bare word that
    is no TOML value is taken as a string (``--set solver.method=ipopt``)."""
    try:
        return tomllib.loads(f"value = {text}")["value"]
    except tomllib.TOMLDecodeError:
        if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-/]*", text):
            return text
        raise InputError(f"{flag}: {text!r} is not a TOML value") from None


def read_toml(path: str | Path, overrides: Sequence[tuple[str, Any, str]] = ()) -> Document:
    """Parse ``path`` and apply ``overrides`` ``(dotted.key, value, origin)``;
    :class:`InputError` with the line for a syntax error."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such task file")
    try:
        text = path.read_text(encoding="utf-8")
        data = tomllib.loads(text)
    except UnicodeDecodeError as err:
        raise InputError(f"{path}: not a UTF-8 text file ({err.reason})") from None
    except tomllib.TOMLDecodeError as err:
        message = getattr(err, "msg", None) or str(err)  # Python >= 3.14: msg, lineno
        at = re.search(r"\(at line (\d+), column \d+\)", message)
        lineno = getattr(err, "lineno", None) or (at and at.group(1))
        message = message[: at.start()].strip() if at else message
        where = f"{path}:{lineno}" if lineno else f"{path}"
        raise InputError(f"{where}: invalid TOML: {message}") from None
    overridden: dict[Key, str] = {}
    for dotted, value, origin in overrides:
        parts = dotted.split(".")
        if len(parts) < 2 or not all(parts):
            raise InputError(f"{origin}: expected TABLE.KEY=VALUE, got {dotted!r}")
        node = data
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise InputError(f"{origin}: [{part}] is not a table in {path}")
        node[parts[-1]] = value
        overridden[tuple(parts)] = origin
    return Document(path, data, text, overridden)
