"""The package layout's layers (docs/architecture.md, "The layers"): read from the code's own imports.

Every import of a module of ``arshadow`` (at module level or inside a function; annotations under
``TYPE_CHECKING`` excepted) names the top-level unit it comes from (a package such as ``frame``, or a
foundation module such as ``io``). A unit may import from its own layer or the layers below, never from a
layer above, and the units' import graph has no cycle.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "arshadow"

#: each top-level unit of arshadow/ and its layer (docs/architecture.md)
LAYERS = {
    "errors": 0, "_check": 0, "transforms": 0, "io": 0, "__version__": 0,
    "camera": 1,
    "compose": 2,
    "geometry": 3, "lights": 3,
    "tracking": 4, "shading": 4,
    "estimate": 5, "synth": 5,
    "renderer": 6,
    "plan": 7,
    "scene": 8,
    "gl": 9,
    "frame": 10,
    "video": 11, "photos": 11, "export": 11,
    "cli": 12, "bench": 12, "demo": 12, "preview": 12, "notebook": 12, "__main__": 12, "__init__": 12,
}  # fmt: skip


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            out.update(id(n) for n in ast.walk(node))
    return out


def import_edges() -> dict[tuple[str, str], list[str]]:
    """``{(importer unit, imported unit): [where, ...]}`` over every module of the package."""
    edges: dict[tuple[str, str], list[str]] = defaultdict(list)
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        module = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        package = module if rel.name == "__init__" else module.rsplit(".", 1)[0]
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = _type_checking_nodes(tree)
        for node in ast.walk(tree):
            if id(node) in skip or not isinstance(node, ast.ImportFrom | ast.Import):
                continue
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names if a.name.startswith("arshadow.")]
            elif node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
                targets = [target] if node.module else [f"{target}.{a.name}" for a in node.names]
            elif (node.module or "").startswith("arshadow."):
                targets = [node.module or ""]
            else:
                continue
            for t in targets:
                a, b = _unit(module), _unit(t)
                if a != b and b != "__init__":
                    edges[(a, b)].append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}")
    return edges


def test_every_unit_has_a_layer():
    units = {
        p.stem if p.is_file() else p.name
        for p in PACKAGE.iterdir()
        if p.suffix == ".py" or (p / "__init__.py").is_file()
    }
    assert units - set(LAYERS) == set(), (
        "give each new top-level module or package a layer (and a row in docs/architecture.md)"
    )


def test_no_import_points_up_a_layer():
    up = {f"{a} -> {b}": where[:3] for (a, b), where in import_edges().items() if LAYERS[b] > LAYERS[a]}
    assert up == {}


def test_no_cycle_between_units():
    graph: dict[str, set[str]] = defaultdict(set)
    for a, b in import_edges():
        graph[a].add(b)
    state: dict[str, int] = {}

    def visit(u: str, path: list[str]) -> None:
        state[u] = 1
        for v in sorted(graph[u]):
            if state.get(v) == 1:
                pytest.fail("import cycle: " + " -> ".join([*path, u, v]))
            if v not in state:
                visit(v, [*path, u])
        state[u] = 2

    for u in sorted(graph):
        if u not in state:
            visit(u, [])


def test_only_gl_imports_moderngl():
    users = sorted(
        str(p.relative_to(PACKAGE.parent))
        for p in PACKAGE.rglob("*.py")
        if "moderngl" in {n.split(".")[0] for n in _imported_names(p)} and "gl" not in p.relative_to(PACKAGE).parts[:1]
    )
    assert users == []


def _imported_names(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names.add(node.module)
    return names


def test_every_package_data_pattern_matches_a_file():
    """pyproject's ``[tool.setuptools.package-data]`` ships files: a pattern that matches none is a stale line
    (the wheel's demo data are mapped from the repository's samples/ and calib/, setup.py's DEMO_DATA)."""
    import tomllib

    root = PACKAGE.parent
    data = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]["package-data"]
    mapped = {"arshadow.demo_data.samples": root / "samples", "arshadow.demo_data.calib": root / "calib"}
    empty = [
        f"{pkg}: {pattern}"
        for pkg, patterns in data.items()
        for pattern in patterns
        if not list(mapped.get(pkg, root.joinpath(*pkg.split("."))).glob(pattern))
    ]
    assert empty == []
