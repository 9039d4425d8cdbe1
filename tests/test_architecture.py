"""Dependencies point inward: the pure cores never import the edges or asyncio."""

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CORES = ("perception", "mapping", "planning")
FORBIDDEN = {"companion", "hil", "asyncio", "aiomqtt", "mavsdk", "depthai"}


def imported_top_level_names(path: Path) -> set[str]:
    """Top-level module names imported anywhere in a Python file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize("core", CORES)
def test_core_imports_no_edge_module(core: str) -> None:
    offenders = {
        str(path.relative_to(REPO)): sorted(imported_top_level_names(path) & FORBIDDEN)
        for path in (REPO / core).rglob("*.py")
    }
    offenders = {path: names for path, names in offenders.items() if names}
    assert not offenders, f"pure cores must not import edges/asyncio: {offenders}"


def test_the_checker_sees_a_violation(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text("import asyncio\nfrom companion.config import Settings\n")
    assert imported_top_level_names(bad) >= {"asyncio", "companion"}
