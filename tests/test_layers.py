"""The package's import structure (issue 19, item 10): every module imports, and nothing imports in a circle.

The graph is read from the source with ``ast`` (every ``import`` and ``from ... import``,
at the top of a module or inside a function: a lazy import is still a dependency), so a new
cycle fails here before anyone trips over it at run time. Two levels:

* modules: no module may depend on itself through others (``yuv`` -> ``_numba_kernels`` ->
  ``yuv`` was one; ``timeline`` -> ``readers`` -> ``timeline`` another);
* rooms (``lipsync.X``: a subpackage or a top-level module): the rooms form a DAG, so each
  depends only on rooms below it (the failure message prints the cycle and the imports
  that close it).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path
from typing import Dict, List, Set

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "lipsync"
#: Modules that run a program when imported (``python -m``): not imported by the test.
ENTRY_POINTS = {"lipsync.__main__", "lipsync.bench.__main__"}
#: The Blender add-on's source, shipped as data: it imports ``bpy`` and runs inside Blender
#: only (tests/test_blender.py imports it there).
BLENDER_ADDON = "lipsync.blender.addon."


def modules() -> Dict[str, Path]:
    out = {}
    for path in sorted(PKG.rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def import_graph() -> Dict[str, Set[str]]:
    """Module -> the lipsync modules it imports (a name imported from a package that is a
    submodule counts as that submodule)."""
    mods = modules()
    graph: Dict[str, Set[str]] = {}
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        deps: Set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            targets: List[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".") if is_pkg else name.split(".")[:-1]
                    base = base[:len(base) - (node.level - 1)]
                    module = ".".join(base + ([node.module] if node.module else []))
                else:
                    module = node.module or ""
                targets = [f"{module}.{a.name}" if f"{module}.{a.name}" in mods else module for a in node.names]
            for t in targets:
                while t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in mods and t != name:
                    deps.add(t)
        graph[name] = deps
    return graph


def cycles(graph: Dict[str, Set[str]]) -> List[List[str]]:
    """Strongly connected components with more than one node (Tarjan, iterative)."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    found: List[List[str]] = []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def room(module: str) -> str:
    return ".".join(module.split(".")[:2])


def test_the_graph_finder_sees_a_cycle():
    # the checker itself: a made-up graph with one cycle and a tail
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(g) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_every_module_imports():
    # In a fresh interpreter (importing the face models, dask and selenium here would
    # grow this process for the rest of the suite).
    names = sorted(m for m in modules() if m not in ENTRY_POINTS and not m.startswith(BLENDER_ADDON))
    code = ("import importlib, sys\nbad = []\nfor n in sys.argv[1:]:\n    try:\n        importlib.import_module(n)\n"
            "    except Exception as exc:\n        bad.append(f'{n}: {type(exc).__name__}: {exc}')\n"
            "print('\\n'.join(bad))\nsys.exit(1 if bad else 0)\n")
    run = subprocess.run([sys.executable, "-c", code, *names], capture_output=True, text=True, cwd=ROOT,
                         timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr[-2000:]
    assert len(names) > 100


def test_no_module_imports_itself_through_others():
    found = cycles(import_graph())
    assert not found, f"import cycles between modules: {found}"


def test_rooms_only_depend_on_rooms_below_them():
    graph = import_graph()
    rooms: Dict[str, Set[str]] = {}
    why: Dict[tuple, List[str]] = {}
    for m, deps in graph.items():
        rooms.setdefault(room(m), set())
        for d in deps:
            if room(d) != room(m):
                rooms[room(m)].add(room(d))
                why.setdefault((room(m), room(d)), []).append(f"{m} -> {d}")
    found = cycles(rooms)
    detail = [f"{a} -> {b}: {why[(a, b)][:3]}" for comp in found for a in comp for b in comp if (a, b) in why]
    assert not found, "rooms importing each other:\n" + "\n".join(detail)
    assert "lipsync.readers" in rooms["lipsync.writers"] and "lipsync.motion" in rooms["lipsync.readers"]
