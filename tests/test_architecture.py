"""The package's layers: data flows one way (Lie groups → robots → dynamics → problem →
formulations → solvers → planning → verification, visualization, benchmarks, CLI), so no two
sub-packages import each other, however indirectly, and the lower layers import nothing above
them. Imports made only for type checking (``if TYPE_CHECKING:``) do not count."""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "mbplan"


@cache
def package_imports() -> dict[str, set[str]]:
    """Sub-package (or top-level module) → the other sub-packages it imports at run time."""
    edges: dict[str, set[str]] = {}
    for path in PACKAGE.rglob("*.py"):
        unit = path.relative_to(PACKAGE).parts[0].removesuffix(".py")
        tree = ast.parse(path.read_text())
        typing_only = {
            id(node)
            for block in ast.walk(tree)
            if isinstance(block, ast.If) and "TYPE_CHECKING" in ast.dump(block.test)
            for stmt in block.body
            for node in ast.walk(stmt)
        }
        for node in ast.walk(tree):
            if id(node) in typing_only:
                continue
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
                if node.module == "mbplan":
                    names = [f"mbplan.{alias.name}" for alias in node.names]
            else:
                continue
            for name in names:
                parts = name.split(".")
                if parts[0] == "mbplan" and len(parts) > 1 and parts[1] != unit:
                    edges.setdefault(unit, set()).add(parts[1])
    return edges


def test_no_two_subpackages_import_each_other_even_indirectly():
    edges = package_imports()

    def reaches(start: str, goal: str) -> list[str] | None:
        stack, seen = [[start]], {start}
        while stack:
            path = stack.pop()
            for nxt in sorted(edges.get(path[-1], ())):
                if nxt == goal:
                    return [*path, nxt]
                if nxt not in seen:
                    seen.add(nxt)
                    stack.append([*path, nxt])
        return None

    cycles = [cycle for unit in sorted(edges) if (cycle := reaches(unit, unit))]
    assert not cycles, f"import cycles: {cycles}"


ALLOWED = {
    # a solver knows nothing of robots, problems or formulations
    "solvers": {"engine", "errors", "finite", "shooting", "workspace"},
    "lie": {"errors"},
    "engine": {"errors"},
    # the problem is plain data: no numerical layer, no formulation
    "ocp": {"errors", "residuals", "robots", "validation"},
}


@pytest.mark.parametrize("unit", sorted(ALLOWED))
def test_lower_layers_import_nothing_above_them(unit: str):
    assert package_imports().get(unit, set()) <= ALLOWED[unit]


def test_the_library_imports_neither_benchmarks_nor_the_command_line():
    edges = package_imports()
    users = {u for u, targets in edges.items() if targets & {"benchmarks", "cli"}}
    assert users <= {"benchmarks", "cli", "__main__"}
