"""Issue 27: the master and its settings do not import each other.

``fmugen/cosim/settings.py`` resolved the run settings with ``check_choices`` imported from the master inside
its functions, and the master imported ``resolve`` from the settings inside ``run()``: a circle, hidden by
the imports being late.  ``check_choices`` now lives with the settings, which import nothing of the master.

The walk reads every module of the package (``ast``: every import, also those inside functions, relative ones
resolved) and finds the strongly connected components of the graph; a fresh interpreter then imports the
settings alone and checks that the master's public names are still there.
"""
import ast
import subprocess
import sys
from pathlib import Path

import fmugen

PACKAGE = Path(fmugen.__file__).parent


def _modules() -> dict:
    out = {}
    for p in PACKAGE.rglob("*.py"):
        parts = ("fmugen",) + p.relative_to(PACKAGE).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def import_graph() -> dict:
    """{module: modules of fmugen it imports anywhere in its text}."""
    mods = _modules()
    graph = {}
    for name, path in mods.items():
        pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
                    base = ".".join(parts + ([base] if base else []))
                for a in node.names:
                    edges.add(f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base)
            elif isinstance(node, ast.Import):
                edges.update(a.name for a in node.names)
        graph[name] = {e for e in edges if e in mods and e != name}
    return graph


def cycles(graph) -> list:
    """The strongly connected components with more than one module (Tarjan, iteratively)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(set(comp))
    return out


def test_the_walk_finds_a_circle_where_there_is_one():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(g) == [{"a", "b", "c"}]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_master_and_settings_are_in_no_circle():
    graph = import_graph()
    assert "fmugen.cosim.check_choices" not in graph  # names resolved to their modules
    assert "fmugen.cosim.master" in graph["fmugen.cosim.report"]  # the walk sees ordinary imports ...
    assert "fmugen.cosim.settings" in graph["fmugen.cosim.master"]
    assert "fmugen.cosim.master" not in graph["fmugen.cosim.settings"]
    circles = [c for c in cycles(graph) if {"fmugen.cosim.master", "fmugen.cosim.settings"} & c]
    assert circles == [], circles


def test_a_fresh_interpreter_imports_the_settings_first():
    code = ("import fmugen.cosim.settings as s, fmugen.cosim.master as m; "
            "assert m.check_choices is s.check_choices and m.run and m.SCHEMES and m.EXTRAPOLATIONS; "
            "print(s.check_choices('gs', 'held'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "('gauss-seidel', 'hold')"
