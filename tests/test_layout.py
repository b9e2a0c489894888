"""The package's shape (issue 17): no import circles, no module past 700 lines.

Both hold the layout that CONTRIBUTING.md describes: a change has one room,
and each room stays small enough to read whole.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "saucerfab"

#: the most lines a module of the package may have
MAX_MODULE_LINES = 700


def _modules() -> dict[str, Path]:
    """Dotted module name -> file, for every module of the package."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imported(name: str, path: Path, modules: dict[str, Path], node: ast.Import | ast.ImportFrom) -> list[str]:
    """The package's modules an import statement of module ``name`` names (longest known prefix)."""
    if isinstance(node, ast.Import):
        wanted = [a.name for a in node.names]
    else:
        base = node.module or ""
        if node.level:
            package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
            package = package[: len(package) - node.level + 1]
            base = ".".join(package + ([base] if base else []))
        wanted = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
    found = []
    for target in wanted:
        while target and target not in modules:
            target = target.rpartition(".")[0]
        if target:
            found.append(target)
    return found


def import_graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports anywhere (top level or inside a function).

    A submodule importing its own package (``saucerfab.x.y`` -> ``saucerfab.x``)
    is left out: Python has the package half-made at that moment by design.
    """
    modules = _modules()
    graph: dict[str, set[str]] = defaultdict(set)
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for target in _imported(name, path, modules, node):
                    if target != name and not name.startswith(target + "."):
                        graph[name].add(target)
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_circle_finder_finds_a_circle() -> None:
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


def test_no_import_circles() -> None:
    found = circles(import_graph())
    assert not found, "import circles (move what both sides need to a module both import): " + "; ".join(
        " <-> ".join(g) for g in found
    )


def test_no_module_too_long() -> None:
    long = {
        str(p.relative_to(PACKAGE.parent)): n
        for p in PACKAGE.rglob("*.py")
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert not long, f"modules over {MAX_MODULE_LINES} lines (split along what they do): {long}"


#: the floor plan, top first (issue 41): the front doors (the commands, the batch, the studio, the demo, the
#: numba warm-up); the workflow that owns design -> export -> check -> verify -> report once; the pages
#: (report.html, the 3D viewer, people's words); the stages (the optimizer, the export, the checker, verify,
#: the rasterizers); imaging (pictures in and previews out); the domain model (scene, cups, eyes, printer
#: profiles, heightfields, reflection, relief, the design); the file helpers. A module imports only its own
#: room and the rooms below it. The package's face (``saucerfab/__init__.py``), ``errors`` and ``extras``
#: are the ground every room stands on.
ROOMS = (
    ("saucerfab.cli", "saucerfab.batch", "saucerfab.studio", "saucerfab.demo", "saucerfab.__main__",
     "saucerfab.warmup"),
    ("saucerfab.workflow",),
    ("saucerfab.pages",),
    ("saucerfab.optimize", "saucerfab.fabricate", "saucerfab.check", "saucerfab.verify", "saucerfab.render"),
    ("saucerfab.imaging",),
    ("saucerfab.model",),
    ("saucerfab.files",),
)

#: the modules that stand on the ground, below every room
GROUND = ("saucerfab", "saucerfab.errors", "saucerfab.extras", "saucerfab.samples")


def floor(module: str) -> int:
    """How high ``module``'s room is: 0 on the ground, one more for each room of :data:`ROOMS` below it."""
    for i, room in enumerate(ROOMS):
        if any(module == r or module.startswith(r + ".") for r in room):
            return len(ROOMS) - i
    if module in GROUND:
        return 0
    raise AssertionError(f"{module} stands in no room of the floor plan: put it in one (tests/test_layout.py ROOMS)")


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """``importer -> imported`` for each import of a module in a higher room (the package itself, the public
    API's face, is in none)."""
    return sorted(f"{a} -> {b}" for a, targets in graph.items() if a != "saucerfab"
                  for b in targets if b != "saucerfab" and floor(b) > floor(a))


def test_the_upward_finder_finds_a_stage_importing_the_workflow() -> None:
    graph = {"saucerfab.verify.x": {"saucerfab.workflow.printing"}, "saucerfab.workflow": {"saucerfab.cli.export"},
             "saucerfab.cli.export": {"saucerfab.workflow", "saucerfab.fabricate"},
             "saucerfab.workflow.checks": {"saucerfab.check"}}
    assert upward_imports(graph) == ["saucerfab.verify.x -> saucerfab.workflow.printing",
                                     "saucerfab.workflow -> saucerfab.cli.export"]


def test_every_module_stands_in_a_room() -> None:
    """The top level holds the ground and the front doors only: a new module goes into a room."""
    for module in _modules():
        floor(module)  # raises for a module outside the plan
    top = sorted(p.stem for p in PACKAGE.glob("*.py"))
    assert top == ["__init__", "__main__", "demo", "errors", "extras", "samples", "warmup"], top


def test_the_upward_finder_finds_the_model_importing_a_stage() -> None:
    graph = {"saucerfab.model.mirror": {"saucerfab.render.camera", "saucerfab.files.fileio"},
             "saucerfab.pages.labels": {"saucerfab.optimize.stages"}, "saucerfab.optimize.x": {"saucerfab.pages.y"}}
    assert upward_imports(graph) == ["saucerfab.model.mirror -> saucerfab.render.camera",
                                     "saucerfab.optimize.x -> saucerfab.pages.y"]


def test_no_upward_imports_between_the_rooms() -> None:
    """No room imports a room above it: the stages never import the pages or the workflow, the model no stage."""
    found = upward_imports(import_graph())
    assert not found, ("imports of a higher room (move what both need down into the lower room, or let the "
                       "front door pass it in): " + "; ".join(found))


def test_the_checker_imports_nothing_above_it() -> None:
    """The checker is the base install's whole job: it imports no orchestration (warmup, demo, workflow,
    the front doors) and none of the design's modules, so ``saucerfab check`` stands on its own."""
    above = ("saucerfab.warmup", "saucerfab.demo", "saucerfab.workflow", "saucerfab.cli", "saucerfab.batch",
             "saucerfab.studio", "saucerfab.optimize", "saucerfab.render", "saucerfab.fabricate")
    bad = sorted(f"{m} -> {t}" for m, targets in import_graph().items() if m.startswith("saucerfab.check")
                 for t in targets if t.startswith(above))
    assert not bad, bad
