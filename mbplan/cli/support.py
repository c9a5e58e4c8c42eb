"""What the command line needs besides its parser: argument types that check numbers as they are
parsed, and running a subcommand with one-line errors and clean interrupts.

Exit codes: 0 success, 1 a plan or benchmark that ran but failed (or an I/O error while
writing), 2 a usage error (bad argument, unknown name, impossible request: checked before any
solve), 128 + signal number when interrupted (130 for Ctrl-C, 143 for SIGTERM).
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import NoReturn

from mbplan.errors import MbplanError, WarmStartWarning


def integer(minimum: int) -> Callable[[str], int]:
    """argparse type: an integer ``>= minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {value}")
        return value

    parse.__name__ = "integer"
    return parse


def real(*, positive: bool = True) -> Callable[[str], float]:
    """argparse type: a finite number ``> 0`` (``>= 0`` unless ``positive``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(value) or value < 0 or (positive and value == 0):
            raise argparse.ArgumentTypeError(
                f"must be a finite number {'> 0' if positive else '>= 0'}, got {text!r}"
            )
        return value

    parse.__name__ = "number"
    return parse


def integer_list(minimum: int) -> Callable[[str], tuple[int, ...]]:
    """argparse type: comma-separated integers ``>= minimum``."""
    one = integer(minimum)

    def parse(text: str) -> tuple[int, ...]:
        items = [t.strip() for t in text.split(",")]
        if not all(items):
            raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}")
        return tuple(one(t) for t in items)

    parse.__name__ = "list of integers"
    return parse


def names(text: str) -> tuple[str, ...]:
    """argparse type: comma-separated names, none empty, none twice (the command checks that
    each is known)."""
    items = tuple(t.strip() for t in text.split(","))
    if not all(items) or len(set(items)) != len(items):
        raise argparse.ArgumentTypeError(f"expected distinct comma-separated names, got {text!r}")
    return items


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line (and exit 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def parse(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace | int:
    """The parsed arguments, or the exit code of ``--help`` or of a usage error."""
    try:
        return parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else 2


class Terminated(KeyboardInterrupt):
    """SIGTERM (or SIGHUP), raised in the main thread like Ctrl-C's KeyboardInterrupt."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


@contextmanager
def terminations_raise() -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise :class:`Terminated`, so that ``finally``
    clauses (locks, temporary files) run as for Ctrl-C."""

    def handler(signum: int, frame: object) -> None:
        raise Terminated(signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def run_command(func: Callable[[], int]) -> int:
    """``func()``'s exit code; an :class:`MbplanError` is one line on stderr and exit 2, an
    ``OSError`` one line and exit 1, an interrupt one line and exit 128 + signal; warnings are
    one line each (``mbplan: warning: ...``)."""
    try:
        with terminations_raise(), warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return int(func())
    except (MbplanError, WarmStartWarning) as exc:
        _say(f"error: {exc}")
        return 2
    except KeyboardInterrupt as exc:
        signum = exc.signum if isinstance(exc, Terminated) else signal.SIGINT
        _say(f"interrupted ({signal.Signals(signum).name}); no partial output was written")
        return 128 + int(signum)
    except OSError as exc:
        where = f": {exc.filename}" if exc.filename else ""
        _say(f"error: {exc.strerror or exc}{where}")
        return 1


def _show_warning(
    message: Warning | str, category: type[Warning], *args: object, **kw: object
) -> None:
    if not issubclass(category, DeprecationWarning | PendingDeprecationWarning):
        _say(f"warning: {message}")


def _say(text: str) -> None:
    print(f"mbplan: {text}", file=sys.stderr, flush=True)


def add_constraint_option(parser: argparse.ArgumentParser, default: str | None = "com") -> None:
    parser.add_argument(
        "--constraint",
        default=default,
        choices=("com", "distance"),
        help="obstacle constraint: link COMs outside the cylinder (paper eq. 62) or coal "
        "distances between link collision geometry and obstacles >= margin",
    )
