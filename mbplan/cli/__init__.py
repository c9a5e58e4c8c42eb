"""The ``mbplan`` command line: the parser and dispatch (:mod:`.main`), ``mbplan plan``
(:mod:`.plan`), ``mbplan bench`` (:mod:`.bench`) and the argument checks they share
(:mod:`.support`)."""

from mbplan.cli.main import main

__all__ = ["main"]
