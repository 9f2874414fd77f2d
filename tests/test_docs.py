"""The documentation: the site builds with warnings as errors, its API reference covers every
public name of the four packages, the env cards' arguments table covers every config field,
and the README keeps the shape a newcomer reads in two minutes."""

import ast
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("envs", "topo", "fusion", "agents")

pytest.importorskip("mkdocs", reason="the docs extra: pip install -e '.[docs]'")


def _hooks():
    spec = importlib.util.spec_from_file_location("topomerge_docs",
                                                  ROOT / "docs" / "_hooks" / "topomerge_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-4000:]
    return out


def _module_path(name: str) -> Path:
    path = ROOT.joinpath(*name.split("."))
    return path / "__init__.py" if path.is_dir() else path.with_suffix(".py")


def public_names(module: str) -> list[str]:
    """``__all__`` if the module defines it, else its top-level public functions, classes and
    assigned names (read from the source, so optional extras need not be installed)."""
    tree = ast.parse(_module_path(module).read_text(encoding="utf-8"))
    names: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            return list(ast.literal_eval(node.value))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.append(node.name)
        elif isinstance(node, ast.Assign):
            names += [t.id for t in node.targets if isinstance(t, ast.Name)]
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.append(node.target.id)
    return [n for n in names if not n.startswith("_")]


def test_site_builds_strict_with_every_page(site):
    for page in ("index.html", "envs/two_robot_explore_v0/index.html",
                 "envs/multi_robot_explore_v0/index.html", "fusion/index.html",
                 "api/fusion/index.html", "changelog/index.html", "results/index.html",
                 "search/search_index.json"):
        assert (site / page).is_file(), page
    assert (site / "paper_fig8_merged.png").is_file()


def test_api_reference_covers_every_public_name(site):
    from mkdocstrings import Inventory

    with open(site / "objects.inv", "rb") as fh:
        inventory = Inventory.parse_sphinx(fh)
    hooks = _hooks()
    missing = []
    for package in PACKAGES:
        for module in hooks.public_modules(package):
            if module not in inventory:
                missing.append(module)
            missing += [f"{module}.{name}" for name in public_names(module)
                        if f"{module}.{name}" not in inventory]
    assert not missing, f"not in the API reference: {missing}"


def test_public_modules_cover_the_packages():
    modules = _hooks().public_modules("fusion")
    assert {"fusion", "fusion.icp", "fusion.decision", "fusion.evaluation.evaluate",
            "fusion.structural", "fusion.calibration"} <= set(modules)
    assert not [m for m in modules if "._" in m]


def test_arguments_table_covers_every_config_field():
    from envs.explore.config import EnvConfig

    rows = {row[0]: row for row in _hooks().argument_rows()}
    config = EnvConfig()
    for group in ("world", "robot", "sonar", "mapping", "comm"):
        for field in type(getattr(config, group)).__dataclass_fields__:
            assert f"{group}.{field}" in rows
    assert rows["sonar.max_range"][2] == f"`{config.sonar.max_range!r}`"
    assert all(row[3] for row in rows.values())


def test_env_cards_read_the_manual_and_the_config(site):
    card = (site / "envs" / "two_robot_explore_v0" / "index.html").read_text(encoding="utf-8")
    assert "sonar.max_range" in card and "Worked example" in card and "Version History" in card


def test_manual_sections_are_found():
    hooks = _hooks()
    assert "coverage_reward" in hooks.manual_section("Rewards")
    with pytest.raises(KeyError, match="env manual has no section 'Nope'"):
        hooks.manual_section("Nope")


def test_readme_shape():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 150
    quick = next(i for i, line in enumerate(lines) if line.lower().startswith("## quick start"))
    assert quick < 60
    text = "\n".join(lines)
    assert "make demo" in text and "make test" in text
    prose, in_code = [], False
    for line in lines:
        if line.startswith("```"):
            in_code = not in_code
        elif not in_code and not line.startswith("|") and not line.startswith("!["):
            prose.append(re.sub(r"`[^`]*`|\([^)]*\.(?:md|png|gif)\)|\[[^\]]*\]", "", line))
    numbers = re.findall(r"\d+(?:[.,]\d+)*", " ".join(prose))
    assert len(numbers) <= 20, numbers
