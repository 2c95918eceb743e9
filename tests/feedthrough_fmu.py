"""Third-party FMUs with direct feedthrough, made here from C sources this file writes (no binaries, no code
from elsewhere), for the master's feedthrough tests (tests/test_cosim_feedthrough.py).

Two masses joined by a stiff spring-damper, split across two Co-Simulation FMUs; the spring's force is an
*output computed from the inputs* (direct feedthrough), as many tool-exported FMUs give a force:

* ``mass`` (A): x' = v, m v' = F + f - c v, the drive f rising smoothly to f0 (f'' = W^2 (f0 - f) - 2 W f');
  input F [N]; outputs x [m], v [m/s] (states: no feedthrough, ``dependencies=""``);
* ``spring`` (B): x2' = v2, m2 v2' = -F - c2 v2 with the output F = k (x2 - x_in) + d (v2 - v_in), inputs
  x_in [m], v_in [m/s] (``dependencies`` names both inputs); output x2 [m] (a state).

Each FMU integrates with classical RK4 on sub-steps of at most 1e-5 s, gets and sets its state, and has no
directional derivatives or output derivatives (the FMI part: ``third_party_fmu.rk4_source``).  ``interpolate=False``: ``canInterpolateInputs="false"``, the
inputs are held over a step (fmi2SetRealInputDerivatives refuses); ``interpolate=True``: the inputs follow the
polynomial the master sends (orders 1-3, from the time they were set), and an output read after a step uses
the inputs at the step's end.  The system is linear: the exact solution is expm(A t) x0.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from third_party_fmu import compile_fmu, model_description, rk4_source

M_A, C_A, M_B, C_B, K, D, F0, W = 1.0, 20.0, 2.0, 40.0, 4.0e4, 5.0, 100.0, 20.0

# A: 0 x, 1 v, 2 m, 3 c, 4 F (in), 5 f0.  B: 0 F (out), 1 x2, 2 m2, 3 c2, 4 x_in, 5 v_in, 6 d, 7 k
NR, NY = 8, 4
MODEL_C = r"""
#ifdef SPRING
static double force(const Comp *c, const double *y, double t) {  /* direct feedthrough of x_in, v_in */
    return c->r[7] * (y[0] - in(c, 4, t)) + c->r[6] * (y[1] - in(c, 5, t));
}
#endif

static void start(Comp *c) {
#ifdef SPRING
    c->r[2] = MB; c->r[3] = CB; c->r[6] = DD; c->r[7] = KK;
#else
    c->r[2] = MA; c->r[3] = CA; c->r[5] = F0;
#endif
}

static void rhs(const Comp *c, double t, const double *y, double *dy) {
#ifdef SPRING
    dy[0] = y[1];
    dy[1] = (-force(c, y, t) - c->r[3] * y[1]) / c->r[2];
    dy[2] = dy[3] = 0;
#else
    dy[0] = y[1];
    dy[1] = (in(c, 4, t) + y[2] - c->r[3] * y[1]) / c->r[2];
    dy[2] = y[3];
    dy[3] = W * W * (c->r[5] - y[2]) - 2 * W * y[3];
#endif
}

static void load(Comp *c, double *y) { (void)c; (void)y; }
static void store(Comp *c, const double *y) { (void)c; (void)y; }

static void outputs(Comp *c) {
#ifdef SPRING
    c->r[0] = force(c, c->y, c->time);
    c->r[1] = c->y[0];
#else
    c->r[0] = c->y[0];
    c->r[1] = c->y[1];
#endif
}
"""

# (name, vr, causality, variability, initial, start, unit): the XML's order is the index dependencies refer to
VARIABLES = {
    "mass": [("x", 0, "output", "continuous", None, None, None), ("v", 1, "output", "continuous", None, None, None),
             ("m", 2, "parameter", "fixed", "exact", M_A, None), ("c", 3, "parameter", "fixed", "exact", C_A, None),
             ("F", 4, "input", "continuous", None, 0.0, None), ("f0", 5, "parameter", "fixed", "exact", F0, None)],
    "spring": [("F", 0, "output", "continuous", None, None, None), ("x2", 1, "output", "continuous", None, None, None),
               ("m", 2, "parameter", "fixed", "exact", M_B, None), ("c", 3, "parameter", "fixed", "exact", C_B, None),
               ("x_in", 4, "input", "continuous", None, 0.0, None), ("v_in", 5, "input", "continuous", None, 0.0, None),
               ("d", 6, "parameter", "fixed", "exact", D, None), ("k", 7, "parameter", "fixed", "exact", K, None)],
}
# ModelStructure/Outputs: (index, dependencies): the spring's force depends on both inputs (feedthrough)
OUTPUTS = {"mass": [(1, ""), (2, "")], "spring": [(1, "5 6"), (2, "")]}


def _xml(ident: str, interpolate: bool) -> str:
    return model_description(ident, f"{{feedthrough-{ident}}}", VARIABLES[ident], OUTPUTS[ident],
                             co_simulation=f'\n      canInterpolateInputs="{str(interpolate).lower()}" '
                                           'maxOutputDerivativeOrder="0"')


def build_system(folder: Path, interpolate: bool, stop: float = 0.2):
    """Compile the two FMUs into ``folder`` and return the CosimSystem coupling them
    (A.x -> B.x_in, A.v -> B.v_in, B.F -> A.F), recording A.x, A.v, B.F, B.x2."""
    from fmugen.cosim.system import CosimSystem, Coupling, Recorded, Unit

    flags = ["-DINTERP"] if interpolate else []
    defs = {"mass": ["-DMA=%r" % M_A, "-DCA=%r" % C_A, "-DF0=%r" % F0, "-DW=%r" % W],
            "spring": ["-DSPRING", "-DMB=%r" % M_B, "-DCB=%r" % C_B, "-DKK=%r" % K, "-DDD=%r" % D]}
    source = rk4_source(NR, NY, MODEL_C)
    paths = {ident: compile_fmu(folder, ident, source, _xml(ident, interpolate), ["-O2", "-std=c99", *flags, *d],
                                source_name="feedthrough.c") for ident, d in defs.items()}
    units = (Unit("A", paths["mass"], "cs", provides_directional_derivative=False),
             Unit("B", paths["spring"], "cs", provides_directional_derivative=False))
    couplings = (Coupling(("A", "x"), ("B", "x_in")), Coupling(("A", "v"), ("B", "v_in")),
                 Coupling(("B", "F"), ("A", "F")))
    recorded = tuple(Recorded(f"{u}.{v}", u, v) for u, v in (("A", "x"), ("A", "v"), ("B", "F"), ("B", "x2")))
    return CosimSystem("feedthrough", units, couplings, recorded, 0.0, stop, 1e-3, order=("A", "B"))


def exact(times, m_a=M_A, c_a=C_A, m_b=M_B, c_b=C_B, k=K, d=D) -> dict:
    """The linear system's solution by the matrix exponential at ``times``: A.x, A.v, B.F, B.x2."""
    import scipy.linalg as sl

    M_A, C_A, M_B, C_B, K, D = m_a, c_a, m_b, c_b, k, d
    # states xa, va, x2, v2, f, f' and a constant 1; F = k (x2 - xa) + d (v2 - va) acts on A, -F on B
    A = np.array([[0, 1, 0, 0, 0, 0, 0],
                  [-K / M_A, -(C_A + D) / M_A, K / M_A, D / M_A, 1 / M_A, 0, 0],
                  [0, 0, 0, 1, 0, 0, 0],
                  [K / M_B, D / M_B, -K / M_B, -(C_B + D) / M_B, 0, 0, 0],
                  [0, 0, 0, 0, 0, 1, 0],
                  [0, 0, 0, 0, -W * W, -2 * W, W * W * F0],
                  [0, 0, 0, 0, 0, 0, 0]], dtype=float)
    x0 = np.array([0, 0, 0, 0, 0, 0, 1.0])
    # propagated from point to point by expm(A dt), one matrix exponential per distinct step (to 1e-15 s)
    times = np.asarray(times, dtype=float)
    xs, phi, x = np.empty((len(times), 7)), {}, sl.expm(A * times[0]) @ x0 if len(times) else x0
    for i, t in enumerate(times):
        if i:
            dt = round(t - times[i - 1], 15)
            if dt not in phi:
                phi[dt] = sl.expm(A * dt)
            x = phi[dt] @ x
        xs[i] = x
    F = K * (xs[:, 2] - xs[:, 0]) + D * (xs[:, 3] - xs[:, 1])
    return {"A.x": xs[:, 0], "A.v": xs[:, 1], "B.F": F, "B.x2": xs[:, 2]}


def error(r, ex=None) -> float:
    """Largest error over the recorded columns at every communication point, relative to each column's range."""
    ex = exact(r.time) if ex is None else ex
    return max(float(np.max(np.abs(r[c] - ex[c])) / np.max(np.abs(ex[c]))) for c in ex)


if __name__ == "__main__":  # every scheme against the exact solution, both variants (python tests/feedthrough_fmu.py)
    import sys
    import tempfile

    from fmugen.cosim import run

    steps = (5e-3, 2e-3, 1e-3, 5e-4, 2.5e-4)
    settings = [("jacobi", "hold"), ("jacobi", "linear"), ("gauss-seidel", "hold"), ("gauss-seidel", "linear"),
                ("iterative", "linear"), ("newton", "hold"), ("newton", "linear")]
    with tempfile.TemporaryDirectory() as tmp:
        for interp in (False, True):
            system = build_system(Path(tmp) / str(interp), interp, stop=0.2)
            print(f"canInterpolateInputs={str(interp).lower()}: max relative error over A.x, A.v, B.F, B.x2 (0.2 s)")
            print("setting".ljust(22) + "".join(f"{h * 1e3:>9.3g}ms" for h in steps) + "   observed orders")
            for scheme, ext in settings:
                errs = []
                for h in steps:
                    r = run(system, scheme, ext, step=h, estimate=False)
                    errs.append(error(r) if r.ok else float("nan"))
                orders = [np.log2(a / b) for a, b in zip(errs, errs[1:])]
                print(f"{scheme}/{ext}".ljust(22) + "".join(f"{e:11.2e}" if e == e else "   diverged" for e in errs)
                      + "   " + " ".join("  -  " if o != o else f"{o:5.2f}" for o in orders), flush=True)
            sys.stdout.flush()
