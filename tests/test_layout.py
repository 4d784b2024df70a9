"""The package layout's dependency direction (issue 24): each package imports only the packages
below it, and no module imports itself back through others (no import loop).

Imports are read from the source (``ast``), at module level and inside functions alike (a lazy
import is still a dependency); ``if TYPE_CHECKING:`` blocks do not count.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "faceforge"

#: package -> the faceforge packages it may import (besides itself and the base modules
#: ``constants`` and ``exceptions``). ``io`` below ``anatomy``/``fit``/``animation``: the
#: template and stage files are read through ``io.stagefiles``, the fit checks the mesh with
#: ``io.mesh_check`` and reads landmarks with ``io.landmarks``.
ALLOWED = {
    "geometry": set(),
    "pbd": set(),
    "mpeg4": set(),
    "io": {"geometry", "mpeg4"},
    "anatomy": {"geometry", "pbd", "io"},
    "fit": {"anatomy", "geometry", "pbd", "io", "mpeg4"},
    "skin": {"anatomy", "geometry", "pbd", "io"},
    "animation": {"anatomy", "skin", "geometry", "pbd", "io", "mpeg4"},
    "landmarks": {"geometry", "io", "mpeg4"},
    "blendshapes": {"animation", "anatomy", "skin", "geometry", "pbd", "io", "mpeg4"},
    "viz": {"anatomy", "fit", "skin", "animation", "geometry", "pbd", "io", "mpeg4"},
    "pipeline": {"anatomy", "fit", "skin", "animation", "blendshapes", "geometry", "pbd", "io", "mpeg4", "viz",
                 "landmarks"},
    "cli": {"pipeline", "io"},
}
BASE = {"constants", "exceptions", "__init__", "__main__"}


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """faceforge modules (dotted) that ``path`` imports, resolved against its package."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for n in ast.walk(node))
    me = _module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "faceforge")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != "faceforge":
                continue
            for a in node.names:   # ``from pkg import module`` names a module when one exists
                sub = f"{mod}.{a.name}"
                out.add(sub if _exists(sub) else mod)
    out.discard(me)
    return out


def _exists(dotted: str) -> bool:
    p = PKG.parent.joinpath(*dotted.split("."))
    return p.with_suffix(".py").is_file() or (p / "__init__.py").is_file()


def _package(dotted: str) -> str:
    parts = dotted.split(".")
    if len(parts) == 1:
        return "__init__"
    return parts[1]


def _graph() -> dict[str, set[str]]:
    return {_module_name(p): _imports(p) for p in sorted(PKG.rglob("*.py"))}


def test_packages_import_only_downwards():
    bad = []
    for mod, deps in _graph().items():
        src = _package(mod)
        if src in BASE:
            continue
        for dep in deps:
            dst = _package(dep)
            if dst in BASE or dst == src:
                continue
            if dst not in ALLOWED.get(src, set()):
                bad.append(f"{mod} -> {dep}")
    assert not bad, "imports against the layout's direction:\n" + "\n".join(sorted(bad))


def test_base_modules_import_nothing_of_faceforge_but_each_other():
    graph = _graph()
    for mod in ("faceforge.constants", "faceforge.exceptions"):
        assert graph[mod] <= {"faceforge.constants", "faceforge.exceptions"}, (mod, graph[mod])


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import loop among modules (as a path a -> ... -> a), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for d in sorted(graph.get(m, ())):
            if d not in graph:
                continue
            if state.get(d) == 1:
                return stack[stack.index(d):] + [d]
            if d not in state:
                found = visit(d)
                if found:
                    return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state:
            found = visit(m)
            if found:
                return found
    return None


def test_no_import_loop_between_modules():
    graph = {m: {d for d in deps if not d.startswith(m + ".")} for m, deps in _graph().items()}
    # a package's __init__ re-exporting its own modules is not a loop of the layout
    graph = {m: {d for d in deps if not (m.startswith(d + ".") and _is_package(d))} for m, deps in graph.items()}
    loop = _cycle(graph)
    assert loop is None, "import loop: " + " -> ".join(loop)


def _is_package(dotted: str) -> bool:
    return (PKG.parent.joinpath(*dotted.split(".")) / "__init__.py").is_file()


@pytest.mark.parametrize("graph, expected", [
    ({"a": {"b"}, "b": {"c"}, "c": {"a"}}, ["a", "b", "c", "a"]),
    ({"a": {"b"}, "b": {"c"}, "c": set()}, None),
])
def test_the_loop_finder_finds_a_loop_and_only_a_loop(graph, expected):
    assert _cycle(graph) == expected


def test_the_direction_check_sees_an_upward_import(tmp_path, monkeypatch):
    """A module of ``geometry`` importing ``faceforge.pipeline`` is reported."""
    fake = tmp_path / "faceforge" / "geometry"
    fake.mkdir(parents=True)
    (tmp_path / "faceforge" / "pipeline").mkdir()
    (tmp_path / "faceforge" / "pipeline" / "__init__.py").write_text("")
    (fake / "up.py").write_text("def f():\n    from faceforge.pipeline import Stage\n")
    monkeypatch.setattr(sys.modules[__name__], "PKG", tmp_path / "faceforge")
    with pytest.raises(AssertionError, match=r"faceforge\.geometry\.up -> faceforge\.pipeline"):
        test_packages_import_only_downwards()


#: folders whose modules the layout describes as a whole (one constraint kind or stage a module)
WHOLE_FOLDERS = {("pbd", "constraints"), ("pipeline", "stages")}


def unnamed_modules(tree: str, modules) -> list[str]:
    """The modules (paths relative to the package, ``skin/cheek.py``) whose name the layout text
    ``tree`` never mentions as a word; private modules and :data:`WHOLE_FOLDERS` are exempt."""
    import re

    out = []
    for rel in modules:
        parts = Path(rel).with_suffix("").parts
        if parts[-1].startswith("_") or tuple(parts[:-1]) in WHOLE_FOLDERS:
            continue
        if not re.search(rf"\b{re.escape(parts[-1])}\b", tree):
            out.append(rel)
    return out


def test_the_architecture_page_names_every_module():
    """docs/ARCHITECTURE.md's layout tree is the map a newcomer reads first: a module it does not
    name is a module nobody will find."""
    text = (PKG.parent / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    tree = text[text.index("```\nfaceforge/"):text.index("Dependency direction")]
    modules = [p.relative_to(PKG).as_posix() for p in PKG.rglob("*.py")]
    assert unnamed_modules(tree, modules) == []
    assert unnamed_modules("skin/ layer, binding", ["skin/layer.py", "skin/cheek.py", "pbd/constraints/x.py",
                                                    "pbd/_kernels.py"]) == ["skin/cheek.py"]
