"""The house keeps its shape: rooms on floors, imports only downwards, no circles.

A *room* is a top-level module or package of ``src/bayescal`` (``calibration/``,
``design.py``). Every import between two rooms must go to a room on a lower
floor (docs/architecture.md draws the floors and says what each room holds).
Imports inside functions and under ``if TYPE_CHECKING:`` count too: they are
dependencies all the same. A module stays under 800 lines and imports no
private name (leading underscore) of another module.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "bayescal"
DOC = Path(__file__).resolve().parents[1] / "docs" / "architecture.md"

#: Packages the floor picture names as a whole, not module by module.
SUMMARISED = {"simulators"}

#: Room -> floor. A room may import rooms on lower floors only.
FLOORS: dict[str, int] = {
    # ground: small shared pieces
    "errors": 0,
    "__init__": 1,
    "units": 1,
    "expressions": 1,
    "optional": 1,
    "atomic": 1,
    "clock": 1,
    "periods": 1,
    "metrics": 1,
    "examples": 1,
    "glossary": 2,
    # numerical kernels: no files, no config, no terminal
    "design": 3,
    "mcmc": 3,
    "simulators": 3,
    "screening": 3,
    "iso9869": 3,
    "emulator": 4,
    "calibration": 5,
    "discrepancy": 6,
    # the study and its inputs
    "config": 7,
    "data": 8,
    "runner": 8,
    # files and reports
    "store": 9,
    "report": 9,
    # orchestration and the user's side
    "pipeline": 10,
    "simulate": 10,
    "cli": 11,
    "demo": 12,
    "__main__": 12,
}

MAX_LINES = 800


def _room(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(SRC.rglob("*.py")):
        parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(path: Path) -> list[tuple[str, list[str], int]]:
    """``(module, names, line)`` of every ``bayescal`` import in a file."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.split(".")[0] == "bayescal":
                found.append((node.module, [a.name for a in node.names], node.lineno))
        elif isinstance(node, ast.Import):
            found += [
                (a.name, [], node.lineno) for a in node.names if a.name.startswith("bayescal")
            ]
    return found


def _room_edges() -> dict[tuple[str, str], list[str]]:
    edges: dict[tuple[str, str], list[str]] = defaultdict(list)
    for module, path in _modules().items():
        for target, names, line in _imports(path):
            targets = [target]
            if target == "bayescal":  # from bayescal import x: the room x, or the package itself
                targets = [f"bayescal.{n}" if not n.startswith("__") else "bayescal" for n in names]
            for t in targets:
                a, b = _room(module), _room(t) if t != "bayescal" else "__init__"
                if a != b:
                    edges[(a, b)].append(f"{path.relative_to(SRC.parent)}:{line}")
    return edges


def test_every_room_has_a_floor() -> None:
    rooms = {_room(m) for m in _modules()}
    assert rooms == set(FLOORS), (
        f"rooms without a floor: {sorted(rooms - set(FLOORS))}; "
        f"floors without a room: {sorted(set(FLOORS) - rooms)}"
    )


def test_imports_run_downwards_only() -> None:
    upward = [
        f"{a} (floor {FLOORS[a]}) imports {b} (floor {FLOORS[b]}) at {', '.join(where)}"
        for (a, b), where in _room_edges().items()
        if FLOORS[b] >= FLOORS[a]
    ]
    assert not upward, "\n".join(upward)


def test_no_import_circle_between_rooms() -> None:
    graph: dict[str, set[str]] = defaultdict(set)
    for a, b in _room_edges():
        graph[a].add(b)
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt) :], nxt]
            if nxt not in state and (circle := visit(nxt)):
                return circle
        stack.pop()
        state[node] = 2
        return None

    for room in sorted(graph):
        if room not in state:
            circle = visit(room)
            assert circle is None, " -> ".join(circle)


def _module_graph() -> dict[str, set[str]]:
    """Module -> the ``bayescal`` modules it imports (type-only and in-function imports too;
    ``from package import module`` counts as the module, ``from module import name`` as
    the module)."""
    modules = _modules()
    graph: dict[str, set[str]] = defaultdict(set)
    for module, path in modules.items():
        for target, names, _ in _imports(path):
            for full in [f"{target}.{n}" for n in names] or [target]:
                found = full if full in modules else target
                while found not in modules and "." in found:
                    found = found.rsplit(".", 1)[0]
                if found != module:
                    graph[module].add(found)
    return graph


def test_no_import_circle_between_modules() -> None:
    # within a room too, and through imports under TYPE_CHECKING (issue 37: type-only
    # circles are circles all the same)
    graph = _module_graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def strong(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for module in sorted(_modules()):
        if module not in index:
            strong(module)
    assert not circles, "import circles: " + "; ".join(" <-> ".join(c) for c in circles)


@pytest.mark.parametrize("module", sorted(_modules()))
def test_module_is_small_and_imports_no_private_name(module: str) -> None:
    path = _modules()[module]
    lines = path.read_text(encoding="utf-8").count("\n")
    assert lines <= MAX_LINES, f"{module} has {lines} lines; split it by meaning"
    private = [
        f"{target}.{name} (line {line})"
        for target, names, line in _imports(path)
        for name in names
        if name.startswith("_") and not name.startswith("__")
    ]
    assert not private, f"{module} imports private names {private}"


def _picture_words(text: str) -> set[str]:
    """The names in the floor picture (the first ``text`` block) of docs/architecture.md."""
    start = text.index("```text") + len("```text")
    return set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text[start : text.index("```", start)]))


def _unnamed_modules(words: set[str]) -> list[str]:
    """Modules whose room or own name the picture does not show."""
    missing = []
    for module in _modules():
        parts = module.split(".")[1:]
        if parts and parts[0] in SUMMARISED:
            parts = parts[:1]
        if not set(parts) <= words:
            missing.append(module)
    return missing


def test_the_picture_names_every_module() -> None:
    missing = _unnamed_modules(_picture_words(DOC.read_text(encoding="utf-8")))
    assert not missing, f"docs/architecture.md's floor picture does not name {missing}"
    # and the check can fail: a picture without calibration's identifiability module
    assert "bayescal.calibration.identifiability" in _unnamed_modules(
        _picture_words(DOC.read_text(encoding="utf-8")) - {"identifiability"}
    )


def test_the_checker_sees_an_upward_import(tmp_path: Path) -> None:
    # The checker itself must be able to fail: an emulator module importing the pipeline.
    fake = tmp_path / "bad.py"
    fake.write_text("from bayescal.pipeline import run\n", encoding="utf-8")
    (target, _, _) = _imports(fake)[0]
    assert FLOORS[_room(target)] > FLOORS["emulator"]
