"""Algebraic loops: couplings around which every output depends directly on the input before it.

An FMU's output depends on its inputs at the same instant when its ModelStructure says so (``<Outputs>``:
``dependencies`` naming an input, or no ``dependencies`` attribute at all, which FMI 2.0 section 2.2.8 reads
as "depends on every input"; ``dependencies=""`` depends on none).  The *feedthrough graph* has the coupled
inputs U_j as nodes and an edge j -> i when input j's FMU has an output that depends on input j and feeds
input i.  Its strongly connected components with a cycle (Tarjan) are the algebraic loops: U = G(U) holds
at every instant, not only across a macro step.

What the master does with one (fmugen/cosim/README.md "Algebraic loops"):

* Jacobi and Gauss-Seidel read every output with the inputs of the step's start: they would run the loop as
  a delay of one macro step, silently.  They refuse it, naming the loop and the scheme that solves it;
* the iterated schemes solve it: their unknowns are the coupled values at the step's end and G evaluates
  every output there, so Newton (and fixed-point iteration, where the loop contracts) meets U = G(U) at
  every communication point;
* at the start time the master solves U = G(U) by Newton on fmi2SetReal / fmi2GetReal at t0
  (:func:`solve_initial`; the Jacobian by finite differences of those reads, no step);
* a loop whose block of I - dG/dU is singular (a loop gain of 1: y = u, u = y) has no unique solution: it is
  reported as singular (:func:`singular_loop`), at t0 before anything runs and by Newton during the run;
* a loop through a Model-Exchange FMU is refused: the ME block evaluates ME couplings once per right-hand
  side and does not solve them.
"""
from __future__ import annotations

import numpy as np

from .errors import CosimError
from .units import UnitFailure

# a loop's block of I - dG/dU whose smallest singular value is below this fraction of its largest (in the
# signals' scales) is singular: finite differences at 1e-6 resolve a gain of 1 to about 1e-10
SINGULAR_RATIO = 1e-8
INITIAL_ITERATIONS = 30


class SingularLoop(Exception):
    """Newton met an algebraic loop whose values are not determined (raised by the interface Jacobian)."""

    def __init__(self, loop: str, ratio: float):
        self.loop, self.ratio = loop, ratio
        super().__init__(f"algebraic loop {loop} is singular (its block of I - dG/dU has condition "
                         f"{1 / max(ratio, 1e-300):.3g}): a loop gain of 1, its values are not determined")


def output_dependencies(unit, outputs, inputs) -> dict:
    """{output name: the names among ``inputs`` it depends on now}, for the ``outputs`` read from ``unit``
    (its ModelStructure; an output absent from <Outputs>, a local variable, depends on none)."""
    declared = {o.variable.name: o for o in getattr(unit.md, "outputs", None) or ()}
    ins = set(inputs)
    out = {}
    for name in outputs:
        o = declared.get(name)
        if o is None:
            out[name] = set()
        elif o.dependencies is None:
            out[name] = set(ins)
        else:
            out[name] = {d.name for d in o.dependencies if d.name in ins}
    return out


def feedthrough_graph(m) -> list:
    """The edges j -> i of the feedthrough graph of master ``m`` (after its interface is resolved), as a
    list of successor lists over U."""
    nu = m.nu
    succ = [[] for _ in range(nu)]
    by_source = {}  # Y index -> the U entries it feeds
    for i in range(nu):
        by_source.setdefault(int(m.S[i]), []).append(i)
    for k, u in enumerate(m.units):
        if not u.n_in:
            continue
        deps = output_dependencies(u, u.out_names, u.in_names)
        for oi, name in enumerate(u.out_names):
            targets = by_source.get(u.out_sl.start + oi, ())
            if not targets or not deps[name]:
                continue
            for j in range(u.in_sl.start, u.in_sl.stop):
                if u.in_names[j - u.in_sl.start] in deps[name]:
                    succ[j].extend(targets)
    return succ


def strongly_connected(succ) -> list:
    """Tarjan's strongly connected components (iteratively), each a sorted list of nodes."""
    n = len(succ)
    index, low, on, stack, comps, counter = [-1] * n, [0] * n, [False] * n, [], [], 0
    for root in range(n):
        if index[root] >= 0:
            continue
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on[root] = True
        work = [(root, iter(succ[root]))]
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if index[w] < 0:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on[w] = True
                    work.append((w, iter(succ[w])))
                elif on[w]:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on[w] = False
                    comp.append(w)
                    if w == v:
                        break
                comps.append(sorted(comp))
    return comps


def algebraic_loops(m) -> list:
    """The algebraic loops of master ``m``: lists of U indices (components of the feedthrough graph with a
    cycle; a coupling of an FMU to itself is refused before)."""
    succ = feedthrough_graph(m)
    return [c for c in strongly_connected(succ) if len(c) > 1 or c[0] in succ[c[0]]]


def chain_length(succ) -> int:
    """The longest path (in edges) of a feedthrough graph without loops: fmi2SetReal/fmi2GetReal passes at
    t0 beyond the first that carry a value from its start to its end."""
    n = len(succ)
    depth, order, seen = [0] * n, [], [False] * n
    for root in range(n):  # a topological order (iterative depth-first search)
        if seen[root]:
            continue
        seen[root] = True
        work = [(root, iter(succ[root]))]
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is None:
                order.append(v)
                work.pop()
            elif not seen[w]:
                seen[w] = True
                work.append((w, iter(succ[w])))
    for v in order:  # successors first
        depth[v] = max((depth[w] + 1 for w in succ[v]), default=0)
    return max(depth, default=0)


def describe(m, loop) -> str:
    """``FMUs 'A', 'B' (A.y -> B.u, B.y -> A.u)``: the FMUs around a loop and its couplings."""
    names = []
    for j in loop:
        for k in (int(m.u_src_unit[j]), int(m.u_owner[j])):
            if m.units[k].name not in names:
                names.append(m.units[k].name)
    return (f"through FMUs {', '.join(repr(n) for n in names)} "
            f"({', '.join(m.coupling_labels[j] for j in loop)})")


def check_scheme(m) -> None:
    """Refuse the loops the chosen scheme would not solve (one line naming the loop and what solves it)."""
    for loop in m.loops:
        what = describe(m, loop)
        me = [m.units[int(m.u_owner[j])].name for j in loop if m.units[int(m.u_owner[j])].kind == "me"]
        if me:
            raise CosimError(f"{m.system.name}: algebraic loop {what}: Model-Exchange FMU {me[0]!r} is in it, and "
                             f"the ME block evaluates its couplings once per right-hand side without solving "
                             f"them; export that FMU for Co-Simulation or break the loop")
        if m.scheme in ("jacobi", "gauss-seidel"):
            raise CosimError(f"{m.system.name}: algebraic loop {what}: every output depends directly on the input "
                             f"before it (ModelStructure <Outputs> dependencies), and {m.scheme} would run the loop "
                             f"as a delay of one macro step; use scheme newton, which solves it at every "
                             f"communication point")


def singular_loop(m, J, scale):
    """(loop description, smallest/largest singular value) of the first loop whose block of I - J (J: dG/dU
    over U, in the signals' scales ``scale``) is singular, else None."""
    for loop in m.loops:
        idx = np.array(loop)
        s = scale[idx]
        block = (np.eye(len(idx)) - J[np.ix_(idx, idx)]) * (s[None, :] / s[:, None])
        sv = np.linalg.svd(block, compute_uv=False)
        ratio = float(sv[-1] / sv[0]) if sv[0] > 0 and np.all(np.isfinite(sv)) else 0.0
        if not ratio >= SINGULAR_RATIO:
            return describe(m, loop), ratio
    return None


def _evaluate(m, U, G) -> int:
    """Set every coupled input to U, read every output, G = F Y[S].  Returns the FMU calls."""
    nu, calls = m.nu, 0
    m.Uset[:nu] = U
    for u in m.units:
        if u.n_in:
            st = u._setReal(u.c, u.in_vr, u.n_in, u.u_ptr)
            calls += 1
            if st > 1:
                raise UnitFailure(u.name, "fmi2SetReal", st, u.messages())
    calls += m._read_all()
    m._coupled(G)
    return calls


def solve_initial(m, U0, tol) -> int:
    """Consistent coupled values at the start time: U0 = G(U0) by Newton on fmi2SetReal / fmi2GetReal (no
    step; the Jacobian by finite differences of those reads, columns only for inputs some output depends
    on).  ``U0`` holds the two passes' values on entry, the solution on exit.  A singular loop or no
    convergence is a CosimError naming the loop.  Returns the FMU calls."""
    nu = m.nu
    succ = feedthrough_graph(m)
    cols = [j for j in range(nu) if succ[j]]
    U = U0[:nu].copy()
    G, Gp = np.zeros(max(nu, 1)), np.zeros(max(nu, 1))
    calls = _evaluate(m, U, G)
    scale = np.maximum(np.abs(U), m.u_nominal[:nu])
    err, it = np.inf, 0
    for it in range(INITIAL_ITERATIONS):
        R = G[:nu] - U
        err = float(np.max(np.abs(R) / (tol * np.maximum(scale, np.abs(U)))))
        if not np.isfinite(err):
            break
        J = np.zeros((nu, nu))
        for j in cols:
            delta = 1e-6 * max(abs(U[j]), scale[j])
            Up = U.copy()
            Up[j] += delta
            calls += _evaluate(m, Up, Gp)
            J[:, j] = (Gp[:nu] - G[:nu]) / delta
        if not np.all(np.isfinite(J)):
            raise CosimError(f"{m.system.name}: an output in algebraic loop {describe(m, m.loops[0])} is not finite "
                             f"at the start time for inputs near {U.tolist()}")
        # singular whatever the residual: y = u, u = y is met by any guess, also the start values
        bad = singular_loop(m, J, scale)
        if bad is not None:
            raise CosimError(f"{m.system.name}: algebraic loop {bad[0]} is singular at the start time (its block of "
                             f"I - dG/dU has condition {1 / max(bad[1], 1e-300):.3g}): a loop gain of 1, so its "
                             f"values are not determined; change a gain or break the loop with an FMU whose "
                             f"output does not depend on its input")
        if err <= 1.0:
            break
        U = U + np.linalg.solve(np.eye(nu) - J, R)
        calls += _evaluate(m, U, G)
    calls += _evaluate(m, U, G)  # the FMUs hold the inputs of the solution (not the last perturbed one)
    R = G[:nu] - U
    err = float(np.max(np.abs(R) / (tol * np.maximum(scale, np.abs(U))))) if nu else 0.0
    if not err <= 1.0:
        worst = max(m.loops, key=lambda lp: float(np.nan_to_num(np.max(np.abs(R[lp])), nan=np.inf)))
        raise CosimError(f"{m.system.name}: algebraic loop {describe(m, worst)}: no consistent values at the start "
                         f"time (Newton's residual {err:.3g} x coupling_tol after {it + 1} iterations)")
    U0[:nu] = G[:nu]
    return calls
