"""MkDocs hook: the pages generated from the code, so they cannot drift from it.

- ``api/<package>.md`` for ``envs``, ``topo``, ``fusion`` and ``agents``: one mkdocstrings
  block per public module (every module whose dotted name has no part starting with ``_``).
- ``<!-- topomerge:arguments -->`` in a page: the env's arguments table, read from the fields,
  defaults and ``Attributes:`` docstrings of ``envs.explore.config``'s dataclasses.
- ``<!-- topomerge:manual SECTION -->``: that ``## SECTION`` of the env manual
  (``envs.explore.env``'s module docstring).

Run by ``mkdocs build`` (``hooks:`` in ``mkdocs.yml``); ``tests/test_docs.py`` imports it to
check the API reference covers every public name.
"""

from __future__ import annotations

import ast
import dataclasses
import pkgutil
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("envs", "topo", "fusion", "agents")
TITLES = {
    "envs": "the environments, their config, world, sensors and mapping",
    "topo": "occupancy grids, topological maps, map files and shared helpers",
    "fusion": "map merging: ICP-SVD, search, structural and grid merges, decision, evaluation",
    "agents": "explorers, datasets, training backends and the `topomerge` command",
}
_MARK = re.compile(r"<!--\s*topomerge:(\w+)\s*([^>]*?)\s*-->")
_ROLE = re.compile(r":\w+:`~?([^`]+)`")  # a Sphinx role in a docstring → inline code


def public_modules(package: str) -> list[str]:
    """Dotted names of ``package`` and its public submodules, found on disk (no import)."""
    base = ROOT / package
    names = [package]
    for info in pkgutil.walk_packages([str(base)], prefix=f"{package}."):
        if any(part.startswith("_") for part in info.name.split(".")):
            continue
        names.append(info.name)
    return sorted(names)


def api_page(package: str) -> str:
    """The markdown of ``api/<package>.md``: a heading and one ``:::`` block per module."""
    lines = [f"# `{package}`", "", f"API reference of `{package}`: {TITLES[package]}.",
             "Generated from the docstrings by `docs/_hooks/topomerge_docs.py`.", ""]
    for name in public_modules(package):
        lines += [f"::: {name}", ""]
    return "\n".join(lines)


def _manual() -> str:
    tree = ast.parse((ROOT / "envs" / "explore" / "env.py").read_text(encoding="utf-8"))
    return ast.get_docstring(tree, clean=True) or ""


def manual_section(title: str) -> str:
    """The body of ``## title`` in the env manual; a ``KeyError`` names the missing title."""
    parts = re.split(r"^## (.+)$", _manual(), flags=re.MULTILINE)
    sections = {parts[i].strip(): parts[i + 1].strip() for i in range(1, len(parts) - 1, 2)}
    if title not in sections:
        raise KeyError(f"env manual has no section {title!r}; it has {sorted(sections)}")
    return _ROLE.sub(r"`\1`", sections[title])


def _attribute_docs(cls: type) -> dict[str, str]:
    """Field name → description from a Google-style ``Attributes:`` docstring section; an entry
    may name several fields (``world, robot: the groups``)."""
    import inspect

    lines = inspect.cleandoc(cls.__doc__ or "").splitlines()
    out: dict[str, str] = {}
    try:
        start = lines.index("Attributes:") + 1
    except ValueError:
        return out
    names: list[str] = []
    for line in lines[start:]:
        if line and not line.startswith(" "):
            break  # the next section
        entry = re.match(r"^    (\w+(?:, \w+)*): (.*)$", line)
        if entry:
            names = entry.group(1).split(", ")
            for name in names:
                out[name] = entry.group(2).strip()
        elif line.strip():
            for name in names:
                out[name] += " " + line.strip()
    return out


def _default(f: dataclasses.Field) -> str:
    if f.default is not dataclasses.MISSING:
        value = f.default
    elif f.default_factory is not dataclasses.MISSING:
        value = f.default_factory()
        if dataclasses.is_dataclass(value):
            return "defaults"
    else:
        return "required"
    return f"`{value!r}`"


def argument_rows() -> list[tuple[str, str, str, str]]:
    """``(parameter, type, default, meaning)`` for every ``EnvConfig`` field, groups expanded
    (``sonar.max_range``); a field without a docstring entry is a ``ValueError``."""
    from envs.explore.config import EnvConfig

    rows: list[tuple[str, str, str, str]] = []

    def walk(cls: type, prefix: str) -> None:
        docs = _attribute_docs(cls)
        for f in dataclasses.fields(cls):
            if f.name not in docs:
                raise ValueError(f"{cls.__name__}.{f.name} has no entry in its class "
                                 f"docstring's Attributes section")
            default = f.default_factory() if f.default_factory is not dataclasses.MISSING \
                else None
            if dataclasses.is_dataclass(default):
                walk(type(default), f"{prefix}{f.name}.")
                continue
            rows.append((f"{prefix}{f.name}", str(f.type), _default(f),
                         _ROLE.sub(r"`\1`", docs[f.name])))

    walk(EnvConfig, "")
    return rows


def arguments_table() -> str:
    """The arguments table in markdown."""
    def cell(text: str) -> str:
        return text.replace("|", "\\|")

    lines = ["| parameter | type | default | meaning |", "|---|---|---|---|"]
    for name, typ, default, meaning in argument_rows():
        lines.append(f"| `{name}` | `{cell(typ)}` | {cell(default)} | {cell(meaning)} |")
    return "\n".join(lines)


def _expand(match: re.Match) -> str:
    kind, arg = match.group(1), match.group(2)
    if kind == "arguments":
        return arguments_table()
    if kind == "manual":
        return manual_section(arg)
    raise ValueError(f"unknown topomerge marker {kind!r}: use 'arguments' or 'manual'")


def on_files(files, config):
    """Adds the generated ``api/<package>.md`` pages."""
    from mkdocs.structure.files import File

    for package in PACKAGES:
        files.append(File.generated(config, f"api/{package}.md", content=api_page(package)))
    return files


def on_page_markdown(markdown, page, config, files):  # noqa: ARG001 - MkDocs' hook signature
    """Expands the ``<!-- topomerge:... -->`` markers."""
    if page.file.src_uri.startswith("notes/"):  # the notes link the results page in the repo
        markdown = markdown.replace("../../benchmarks/RESULTS.md", "../results.md")
    return _MARK.sub(_expand, markdown)


def on_page_content(html, page, config, files):  # noqa: ARG001 - MkDocs' hook signature
    """Drops the Sphinx roles docstrings use (``:class:`X``` renders as ``:class:`` + code)."""
    return re.sub(r":(?:class|func|mod|meth|data|attr|obj|exc):(<code>)~?", r"\1", html)
