"""The house as docs/design/architecture.md draws it: layers whose imports point only down,
fleet/'s rooms in their order, modules and functions of a readable size, and tests that
mirror the packages."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

LAYERS = ("agent", "bridge", "fleet", "mocap_sim", "dashboard", "cli")
"""trustfg's top-level packages from the bottom up; mocap_sim and dashboard stand side by
side on top of fleet (neither imports the other), the command above all."""

FLEET_ROOMS = ("program", "cpu", "bus", "car", "sim", "operator", "recording", "launch", "experiments", "faultlab")
"""fleet/'s modules and sub-packages from the bottom up: each imports only rooms before it."""

SIDE_BY_SIDE = {frozenset({"mocap_sim", "dashboard"})}

MAX_MODULE_LINES, MAX_FUNCTION_LINES, MAX_CAR_AGENT_LINES = 500, 80, 400

NOT_MIRRORED = ("repo",)
"""Test folders of the whole repository (README, docs, packaging, leftovers): no package to mirror."""


def package_files() -> list[Path]:
    skip = {"tests", "benchmarks", "examples", ".venv", "build", "firmware", "docs"}
    return [p for p in sorted(ROOT.rglob("*.py")) if not skip & set(p.relative_to(ROOT).parts)
            and not any(part.startswith(".") for part in p.relative_to(ROOT).parts)]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(["trustfg", *parts])


def imports_of(path: Path) -> set[str]:
    """Absolute trustfg modules a file imports (relative imports resolved)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.startswith("trustfg"):
                found.add(target)
                found.update(f"{target}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name.startswith("trustfg"))
    return found


def graph() -> dict[str, set[str]]:
    modules = {module_name(p): p for p in package_files()}
    return {name: {t for t in imports_of(path) if t in modules and t != name} for name, path in modules.items()}


def layer_of(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS else None


def room_of(module: str) -> str | None:
    parts = module.split(".")
    return parts[2] if len(parts) > 2 and parts[1] == "fleet" and parts[2] in FLEET_ROOMS else None


def test_every_import_points_down_a_layer_or_stays_in_its_own():
    upward = []
    for module, targets in graph().items():
        for target in targets:
            a, b = layer_of(module), layer_of(target)
            if a is None or b is None or a == b:
                continue
            if frozenset({a, b}) in SIDE_BY_SIDE or LAYERS.index(b) > LAYERS.index(a):
                upward.append(f"{module} -> {target}")
    assert upward == []


def test_fleet_rooms_import_only_rooms_below_them():
    upward = []
    for module, targets in graph().items():
        for target in targets:
            a, b = room_of(module), room_of(target)
            if a and b and a != b and FLEET_ROOMS.index(b) > FLEET_ROOMS.index(a):
                upward.append(f"{module} -> {target}")
    assert upward == []


def test_fleet_has_at_most_ten_rooms_and_each_is_listed():
    rooms = sorted(p.stem if p.is_file() else p.name for p in (ROOT / "fleet").iterdir()
                   if (p.suffix == ".py" and p.name != "__init__.py") or (p / "__init__.py").is_file())
    assert len(rooms) <= 10
    assert sorted(FLEET_ROOMS) == rooms


def test_the_import_graph_has_no_cycles():
    edges = graph()
    # imports of a package's own __init__ from its modules are not cycles of code
    state: dict[str, int] = {}
    cycles = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for target in sorted(edges.get(node, ())):
            if node.startswith(target + "."):  # a module importing its own package
                continue
            if state.get(target) == 1:
                cycles.append(" -> ".join(path[path.index(target):] + [target]))
            elif target not in state:
                visit(target, path + [target])
        state[node] = 2

    for node in sorted(edges):
        if node not in state:
            visit(node, [node])
    assert cycles == []


def compiled(node: ast.FunctionDef) -> bool:
    """A numba kernel: one loop the compiler sees whole, not code to be read in steps."""
    return any("njit" in ast.unparse(d) or "jit" in ast.unparse(d) for d in node.decorator_list)


def test_modules_and_functions_stay_readable():
    too_long = []
    for path in package_files():
        text = path.read_text()
        where = path.relative_to(ROOT)
        if text.count("\n") > MAX_MODULE_LINES:
            too_long.append(f"{where}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            lines = getattr(node, "end_lineno", 0) - getattr(node, "lineno", 0) + 1
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and lines > MAX_FUNCTION_LINES \
                    and not compiled(node):
                too_long.append(f"{where}:{node.lineno} {node.name}: {lines} lines")
            if isinstance(node, ast.ClassDef) and node.name == "CarAgent" and lines > MAX_CAR_AGENT_LINES:
                too_long.append(f"{where}: CarAgent {lines} lines")
    assert too_long == []


def mirrors(test: Path) -> bool:
    """tests/X/test_Y.py tests X/Y.py or X/Y/; or X/M.py for Y = M_aspect (one module, one aspect)."""
    folder = ROOT / test.parent.relative_to(ROOT / "tests")
    stem = test.stem.removeprefix("test_")
    names = {p.stem for p in folder.glob("*.py")} | {p.name for p in folder.iterdir() if p.is_dir()} \
        if folder.is_dir() else set()
    return stem in names or any(stem.startswith(name + "_") for name in names if name != "__init__")


def test_tests_mirror_the_packages():
    tests = [p for p in (ROOT / "tests").rglob("test_*.py")
             if p.relative_to(ROOT / "tests").parts[0] not in NOT_MIRRORED]
    assert [str(p.relative_to(ROOT)) for p in tests if not mirrors(p)] == []
