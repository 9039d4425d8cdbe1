"""Every dependency rule that docs/architecture.md states, checked on the imports of the code.

The rules (docs/architecture.md, "Dependency rules"):
1. Layers: geometry < perception, mapping < planning < companion < hil < companion.cli. A
   module imports only from its own package or a lower layer; perception and mapping never
   import each other; planning reads the map only through `mapping.query`.
2. The flight process (companion/, outside companion/cli/) never imports hil/; hil/ never
   imports companion/.
3. The cores (geometry, perception, mapping, planning) import no asyncio, no network or
   hardware library, and no clock, except perception/training/, which times training steps.
4. No import cycles between modules.
5. One home for each concept: no class name is defined twice in the product.
6. No test skips itself.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("geometry", "perception", "mapping", "planning", "companion", "hil")
# Rule 1: what each part may import of ours (besides itself); the most specific prefix wins.
ALLOWED: dict[str, tuple[str, ...]] = {
    "geometry": (),
    "perception": ("geometry",),
    "mapping": ("geometry",),
    "planning": ("geometry", "mapping.query"),
    "companion": ("geometry", "perception", "mapping", "planning"),
    "hil": ("geometry", "perception", "mapping", "planning"),
    "companion.cli": ("geometry", "perception", "mapping", "planning", "companion", "hil"),
}
CORES = ("geometry", "perception", "mapping", "planning")
CORE_FORBIDDEN = {"asyncio", "aiomqtt", "paho", "mavsdk", "pymavlink", "depthai", "socket"}
CLOCK_MODULES = {"time", "datetime"}
CLOCK_ALLOWED = ("perception.training",)


def module_name(path: Path) -> str:
    """`companion/cli/sim.py` -> `companion.cli.sim`; a package's `__init__` is the package."""
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def product_modules() -> dict[str, Path]:
    """Every module of the product's packages, by dotted name."""
    return {
        module_name(path): path
        for package in PACKAGES
        for path in sorted((REPO / package).rglob("*.py"))
    }


def imported_names(path: Path) -> set[str]:
    """Dotted names imported anywhere in a file (`from a.b import c` gives `a.b` and `a.b.c`)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def part_of(module: str) -> str:
    """The part of the layering a module belongs to (the longest matching prefix)."""
    return max(
        (part for part in ALLOWED if module == part or module.startswith(part + ".")), key=len
    )


def within(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def our_imports(path: Path, modules: dict[str, Path]) -> set[str]:
    """The product modules a file imports (a `from m import f` resolves to `m`)."""
    found = set()
    for name in imported_names(path):
        if name in modules:
            found.add(name)
    return found


def layer_violations(modules: dict[str, Path]) -> dict[str, list[str]]:
    """Rule 1 and 2: imports a module's part may not make."""
    bad: dict[str, list[str]] = {}
    for module, path in modules.items():
        part = part_of(module)
        own = part.split(".")[0] if part != "companion.cli" else "companion"
        for target in sorted(our_imports(path, modules)):
            if within(target, own) and not (
                part == "companion" and within(target, "companion.cli")
            ):
                continue
            if not any(within(target, allowed) for allowed in ALLOWED[part]):
                bad.setdefault(module, []).append(target)
    return bad


def test_imports_point_down_the_layers() -> None:
    bad = layer_violations(product_modules())
    assert not bad, f"imports against the layering of docs/architecture.md: {bad}"


def test_the_flight_process_never_imports_the_simulator_and_back() -> None:
    modules = product_modules()
    for module, path in modules.items():
        targets = our_imports(path, modules)
        if within(module, "companion") and not within(module, "companion.cli"):
            assert not [t for t in targets if within(t, "hil")], module
            assert not [t for t in targets if within(t, "companion.cli")], module
        if within(module, "hil"):
            assert not [t for t in targets if within(t, "companion")], module


@pytest.mark.parametrize("core", CORES)
def test_cores_import_no_asyncio_io_library_or_clock(core: str) -> None:
    offenders = {}
    for module, path in product_modules().items():
        if not within(module, core):
            continue
        tops = {name.split(".")[0] for name in imported_names(path)}
        forbidden = CORE_FORBIDDEN | (
            set() if any(within(module, ok) for ok in CLOCK_ALLOWED) else CLOCK_MODULES
        )
        if tops & forbidden:
            offenders[module] = sorted(tops & forbidden)
    assert not offenders, f"pure cores must not import edges, I/O or clocks: {offenders}"


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in graph.get(node, ()):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return cycles


def test_no_import_cycles() -> None:
    modules = product_modules()
    graph = {
        module: {t for t in our_imports(path, modules) if t != module}
        for module, path in modules.items()
    }
    # a package's __init__ re-exporting its modules is not a cycle of theirs
    graph = {m: {t for t in ts if not within(m, t)} for m, ts in graph.items()}
    assert not import_cycles(graph)


def test_each_class_has_one_home() -> None:
    homes: dict[str, list[str]] = defaultdict(list)
    for module, path in product_modules().items():
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ClassDef):
                homes[node.name].append(module)
    twice = {name: where for name, where in homes.items() if len(where) > 1}
    assert not twice, f"classes defined in more than one place: {twice}"


def test_no_test_skips_itself() -> None:
    pattern = re.compile(r"pytest\.mark\.skip(if)?\b|pytest\.skip\(|pytest\.importorskip\(")
    offenders = [
        f"{path.name}:{number}"
        for path in sorted((REPO / "tests").glob("*.py"))
        if path.name != "test_architecture.py"
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if pattern.search(line)
    ]
    assert not offenders, offenders


# ------------------------------------------------------------------ the checker can fail


def test_the_checker_sees_a_layering_violation(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text("import asyncio\nfrom companion.config import Settings\n")
    assert imported_names(bad) >= {"asyncio", "companion.config", "companion.config.Settings"}
    assert part_of("mapping.droan.pose_graph") == "mapping"
    assert part_of("companion.cli.sim") == "companion.cli"
    assert not any(within("hil.world", allowed) for allowed in ALLOWED["companion"])
    assert not any(within("mapping.droan", allowed) for allowed in ALLOWED["planning"])


def test_the_checker_sees_a_cycle() -> None:
    assert import_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []
