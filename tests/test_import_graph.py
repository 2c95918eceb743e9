"""No import circles inside fmugen (issue 27).

Every module's imports are read with ``ast`` (nothing is imported): the
top-level ones and those inside functions alike, since a function-local
import that closes a circle is still a circle, only one that fails later.
The exception are the lazy facades of package ``__init__`` files (PEP 562
``__getattr__`` and wrapper functions such as ``fmugen.build_fmu``): a
package importing its own implementation on first use is the right
direction, and ``from .. import __version__`` of a submodule is no circle
then.  The strongly connected components of that graph (Tarjan) must all be
single modules.
"""
import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "fmugen"

#: circles known and being untied elsewhere; an entry that no longer exists fails the test (remove it then).
KNOWN_PENDING: list = []


def _modules(pkg: Path) -> dict:
    out = {}
    for p in sorted(pkg.rglob("*.py")):
        parts = list(p.relative_to(pkg.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _imports(name: str, path: Path, mods: dict):
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    is_pkg = path.name == "__init__.py"
    here = name.split(".") if is_pkg else name.split(".")[:-1]
    nodes = tree.body if is_pkg else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = here[:len(here) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            # "from .x import y": y is a module of its own or a name in x
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in mods else mod for a in node.names]
        else:
            continue
        for t in targets:
            while t not in mods and "." in t:  # a name inside a module: the module
                t = t.rsplit(".", 1)[0]
            if t in mods and t != name:
                yield t


def import_graph(pkg: Path = PKG) -> dict:
    mods = _modules(pkg)
    return {m: sorted(set(_imports(m, p, mods))) for m, p in mods.items()}


def circles(graph: dict) -> list:
    """Strongly connected components of more than one module, each sorted (Tarjan, iterative)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(graph[root]))]
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
                    work.append((w, iter(graph[w])))
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
                    out.append(sorted(comp))
    return sorted(out)


def test_the_circle_finder_finds_a_circle_and_only_circles():
    g = {"a": ["b"], "b": ["c"], "c": ["a", "d"], "d": [], "e": ["e2"], "e2": ["d"]}
    assert circles(g) == [["a", "b", "c"]]
    assert circles({"x": ["y"], "y": ["x"], "z": ["x"]}) == [["x", "y"]]


def test_the_graph_sees_function_local_imports_but_not_a_package_facade(tmp_path):
    pkg = tmp_path / "pk"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("__version__ = '1'\ndef build():\n    from .sub.b import f\n    return f\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "a.py").write_text("from .. import __version__\nfrom .b import g\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from . import a\n    from pk.sub.a import g\n")
    g = import_graph(pkg)
    assert g["pk.sub.a"] == ["pk", "pk.sub.b"] and g["pk.sub.b"] == ["pk.sub.a"] and g["pk"] == []
    assert circles(g) == [["pk.sub.a", "pk.sub.b"]]


def test_no_import_circles():
    found = circles(import_graph())
    pending = [c for c in found if c in KNOWN_PENDING]
    assert [c for c in found if c not in KNOWN_PENDING] == [], "import circles in fmugen"
    assert pending == KNOWN_PENDING, f"untied, remove from KNOWN_PENDING: {[c for c in KNOWN_PENDING if c not in found]}"
