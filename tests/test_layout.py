"""The package layout is the data flow: `native/` (the C build/load helper and the error base) imports
neither `planner` nor `cosim`, `planner/` never imports `cosim`, `cosim/` stages import only from
themselves or from stages above them, and no module of the three packages is part of an import cycle
(in-function and TYPE_CHECKING imports count: a cycle there still couples the modules)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
# Top to bottom: data flows down this list (README "Layout").
STAGES = ("core", "fmi", "world", "scenario", "record", "navigation", "ssp", "logs", "sweep", "cli")
SHARED = {"cosim", "cosim.errors", "cosim.__main__"}  # entry points and the error base


def _modules(package: str) -> dict[str, Path]:
    modules = {}
    for path in sorted((REPO / package).rglob("*.py")):
        parts = list(path.relative_to(REPO).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = path
    return modules


def _imports(module: str, path: Path, known: dict[str, Path]) -> set[str]:
    """Project modules that `module` imports anywhere in its body."""
    found = set()
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
            target = ".".join(base + ([node.module] if node.module else []))
            # `from package import submodule` depends on the submodule; the package's own
            # __init__ is a dependency only for names that are not submodules.
            submodules = [
                f"{target}.{alias.name}" for alias in node.names if f"{target}.{alias.name}" in known
            ]
            targets = submodules + ([target] if len(submodules) < len(node.names) else [])
        else:
            continue
        found.update(t for t in targets if t in known and t != module)
    return found


def _graph() -> dict[str, set[str]]:
    known = {**_modules("cosim"), **_modules("planner"), **_modules("native")}
    return {module: _imports(module, path, known) for module, path in known.items()}


@pytest.mark.parametrize("package", ["cosim", "planner", "native"])
def test_no_import_cycles(package: str):
    graph = {
        m: {t for t in ts if t.startswith(package)} for m, ts in _graph().items() if m.startswith(package)
    }
    cycles, state = [], {}

    def visit(node: str, stack: list[str]) -> None:
        state[node] = "open"
        stack.append(node)
        for target in sorted(graph[node]):
            if state.get(target) == "open":
                cycles.append(" -> ".join(stack[stack.index(target) :] + [target]))
            elif target not in state:
                visit(target, stack)
        stack.pop()
        state[node] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module, [])
    assert cycles == []


def _stage(module: str) -> int | None:
    parts = module.split(".")
    return STAGES.index(parts[1]) if len(parts) > 1 and parts[1] in STAGES else None


def test_cosim_stages_import_only_upstream():
    graph = _graph()
    assert {m.split(".")[1] for m in graph if m.startswith("cosim.") and m not in SHARED} <= set(STAGES)
    backwards = [
        f"{module} imports {target}"
        for module, targets in sorted(graph.items())
        if module.startswith("cosim") and _stage(module) is not None
        for target in sorted(targets)
        if target.startswith("cosim") and target not in SHARED and _stage(target) > _stage(module)
    ]
    assert backwards == []


def _package(module: str) -> str:
    return module.split(".")[0]


@pytest.mark.parametrize(("package", "never"), [("planner", {"cosim"}), ("native", {"planner", "cosim"})])
def test_shared_packages_never_import_their_users(package: str, never: set[str]):
    graph = _graph()
    assert any(_package(m) == package for m in graph)
    assert [
        f"{m} -> {t}"
        for m, ts in sorted(graph.items())
        if _package(m) == package
        for t in sorted(ts)
        if _package(t) in never
    ] == []
