"""MkDocs hook: the API reference, generated at build time from the package's files.

Every module of ``mbplan`` (found by walking ``mbplan/``, nothing imported, no hand-written
list) gets a page ``api/<dotted.name>.md`` holding one mkdocstrings directive, and the
"API reference" entry of the navigation becomes the package tree. A module that moves or is
added needs no change here. The hook also makes links from the pages to committed benchmark
results (``../benchmarks/results/...``, which resolve on a repository browser) work on the site:
those files are added to the build under ``results/`` and the links rewritten to them; a link to
a result file that does not exist is reported as a warning (an error with ``--strict``).
"""

from __future__ import annotations

import ast
import logging
import posixpath
import re
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "mbplan"
RESULTS = ROOT / "benchmarks" / "results"
RESULT_SUFFIXES = {".md", ".png", ".svg", ".json"}
log = logging.getLogger("mkdocs.hooks.gen_api")


def modules() -> list[str]:
    """Dotted names of every public module and package under ``mbplan/``, sorted."""
    names = []
    for path in sorted((ROOT / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        if any(p.startswith("_") for p in parts) or "__pycache__" in path.parts:
            continue
        if not (path.parent / "__init__.py").exists():
            continue
        names.append(".".join(parts))
    return sorted(set(names))


def _summary(name: str) -> str:
    """The first line of a module's docstring, read with ``ast`` (nothing imported)."""
    base = ROOT / Path(*name.split("."))
    path = base / "__init__.py" if base.is_dir() else base.with_suffix(".py")
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    line = doc.strip().split("\n\n", 1)[0].replace("\n", " ")
    return line.replace("|", "\\|")


def _nav_tree(names: list[str]) -> list:
    """Nested navigation entries: a package is a section whose first page is its own."""

    def children(prefix: str) -> list:
        depth = prefix.count(".") + 1
        entries: list = []
        for name in names:
            if not name.startswith(prefix + ".") or name.count(".") != depth:
                continue
            sub = [n for n in names if n.startswith(name + ".")]
            page = f"api/{name}.md"
            entries.append({name: [page, *children(name)]} if sub else {name: page})
        return entries

    return ["api/index.md", {PACKAGE: f"api/{PACKAGE}.md"}, *children(PACKAGE)]


def on_config(config):
    """Put the generated pages into the "API reference" entry of ``nav``."""
    tree = _nav_tree(modules())
    for i, entry in enumerate(config["nav"] or []):
        if isinstance(entry, dict) and "API reference" in entry:
            config["nav"][i] = {"API reference": tree}
    return config


def on_files(files: Files, config) -> Files:
    """Add one page per module, the reference's index and the cited benchmark results."""
    names = modules()
    for name in names:
        content = f"# `{name}`\n\n::: {name}\n"
        files.append(File.generated(config, f"api/{name}.md", content=content))
    rows = "\n".join(f"| [`{n}`]({n}.md) | {_summary(n)} |" for n in names)
    index = (
        "# API reference\n\n"
        "Generated from the docstrings of every module of the package (one page each).\n\n"
        f"| module | summary |\n|---|---|\n{rows}\n"
    )
    files.append(File.generated(config, "api/index.md", content=index))
    for path in sorted(RESULTS.rglob("*")):
        if path.is_file() and path.suffix in RESULT_SUFFIXES:
            uri = "results/" + path.relative_to(RESULTS).as_posix()
            files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files


_LINK = re.compile(r"(\]\()([^)\s#]+)(#[^)\s]*)?(\))")


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Rewrite links from a docs page to ``benchmarks/results/...`` to the copies in the build."""
    src = page.file.src_uri
    if src.startswith("api/") or src.startswith("results/"):
        return markdown
    docs_rel = Path(config["docs_dir"]).resolve().relative_to(ROOT).as_posix()

    def rewrite(m: re.Match) -> str:
        target = m.group(2)
        if "://" in target or target.startswith("/"):
            return m.group(0)
        in_repo = posixpath.normpath(posixpath.join(docs_rel, posixpath.dirname(src), target))
        if not in_repo.startswith("benchmarks/results/"):
            return m.group(0)
        if not (ROOT / in_repo).exists():
            log.warning("%s links to %s, which does not exist", src, in_repo)
            return m.group(0)
        rest = in_repo.removeprefix("benchmarks/results/")
        if (ROOT / in_repo).is_dir():
            rest = posixpath.join(rest, "results.md")
            if not (RESULTS / rest).exists():
                log.warning("%s links to the folder %s, which has no results.md", src, in_repo)
                return m.group(0)
        new = posixpath.relpath(f"results/{rest}", posixpath.dirname(src) or ".")
        return f"{m.group(1)}{new}{m.group(3) or ''}{m.group(4)}"

    return _LINK.sub(rewrite, markdown)
