"""Issue 27: a battery of hostile systems and settings against the master's API (``fmugen.cosim.run``).

Every case is refused in one line (a CosimError) or runs with a clear status: ``ok`` with values that match
the closed form of the system, or ``failed`` with a FailureReport naming the FMU.  Counted per outcome:

* ``crash``: any other exception (a traceback for the user);
* ``silent-wrong``: status ok where the case is invalid, values off the closed form, or a non-finite value;
* ``refused``: a one-line CosimError (``refused-multiline``: with a newline);
* ``failed``: a run that stopped with a FailureReport; ``ok``: a run that matched the closed form.

The base system is a chain of third-party FMUs (``tests/third_party_fmu.py``): lag L1 (u = 1) -> gain G
(y = a u + b) -> lag L2, with time constant T, whose L2.y is (a + b)(1 - e^{-t/T}) - a (t/T) e^{-t/T}.
The cases are deterministic (a seeded generator picks hostile names, numbers and mutations);
``python tests/test_cosim_hostile.py`` prints the counts per class and per kind of case (a case still running
after 30 s counts as ``hang`` there).
"""
from __future__ import annotations

import math
import random
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fmugen.cosim import run
from fmugen.cosim.errors import CosimError
from fmugen.cosim.system import Coupling, CosimSystem, Recorded, Unit

from third_party_fmu import build_gain

T, A, B, STOP, H = 0.1, 2.0, 0.5, 0.1, 0.01
NAMES = ["", "y ", "Y", "y\n", "ü", "x" * 300, "u", "k", "a", "../y", "y;rm", "<y/>", "None", "0"]
NUMBERS = [0.0, -0.01, math.nan, math.inf, -math.inf, 1e-300, 1e300, "0.01", None, True, "abc", [0.01]]


def build(folder: Path) -> dict:
    f = {"gain": build_gain(folder, "gain"), "lag": build_gain(folder, "lag", dependencies="", lag=True),
         "gain_rad": build_gain(folder, "gain_rad", unit="rad"),
         "lag_nan": build_gain(folder, "lag_nan", dependencies="", lag=True, cflags=["-DNAN_AFTER=0.035"]),
         "lag_error": build_gain(folder, "lag_error", dependencies="", lag=True,
                                 cflags=["-DSTATUS_AFTER=0.035", "-DSTATUS=fmi2Error"]),
         "lag_discard": build_gain(folder, "lag_discard", dependencies="", lag=True,
                                   cflags=["-DSTATUS_AFTER=0.035", "-DSTATUS=fmi2Discard"]),
         "lag_nostate": build_gain(folder, "lag_nostate", dependencies="", lag=True,
                                   capabilities={"canGetAndSetFMUstate": "false"})}
    return f


def base(f, lag1="lag", gain="gain", lag2="lag") -> CosimSystem:
    units = (Unit("L1", f[lag1], "cs", {"u": 1.0, "T": T}), Unit("G", f[gain], "cs", {"a": A, "b": B}),
             Unit("L2", f[lag2], "cs", {"T": T}))
    couplings = (Coupling(("L1", "y"), ("G", "u")), Coupling(("G", "y"), ("L2", "u")))
    recorded = (Recorded("L1.y", "L1", "y"), Recorded("G.y", "G", "y"), Recorded("L2.y", "L2", "y"))
    return CosimSystem("chain", units, couplings, recorded, 0.0, STOP, H, order=("L1", "G", "L2"))


def exact_l2(t):
    return (A + B) * (1 - math.exp(-t / T)) - A * (t / T) * math.exp(-t / T)


def cases(f, seed: int = 27) -> list:
    """(kind, expected, system, run keywords): expected "refuse", "fail" or "ok"."""
    rng = random.Random(seed)
    s = base(f)
    out = []
    c0, c1 = s.couplings

    def add(kind, expected, system, **kw):
        out.append((kind, expected, system, kw))

    for name in NAMES:  # unknown or wrong variables at either end (u, a, k exist: an input, a parameter)
        add("unknown/wrong source variable", "refuse", replace(s, couplings=(replace(c0, source=("L1", name)), c1)))
        add("unknown/wrong target variable", "ok" if name == "u" else "refuse",
            replace(s, couplings=(replace(c0, target=("G", name)), c1)))
        add("unknown FMU in a coupling", "refuse", replace(s, couplings=(replace(c0, source=(name, "y")), c1)))
        add("unknown recorded variable", "ok" if name in ("u", "a") else "refuse",
            replace(s, recorded=s.recorded + (Recorded("x", "L2", name),)))
        add("start value of an unknown variable", "ok-any" if name in ("u", "a") else "refuse",
            replace(s, units=(replace(s.units[0], start_values={name: 1.0}),) + s.units[1:]))
    for src, dst in ((("L1", "k"), ("G", "u")), (("L1", "y"), ("G", "k"))):  # Real -> Integer
        add("type mismatch Real/Integer", "refuse", replace(s, couplings=(Coupling(src, dst), c1)))
    for src, dst in ((("L1", "y"), ("G", "y")), (("L1", "u"), ("G", "u")), (("L1", "a"), ("G", "u")),
                     (("L1", "y"), ("G", "a")), (("L1", "y"), ("G", "T"))):  # causality
        add("causality error", "refuse", replace(s, couplings=(Coupling(src, dst), c1)))
    s_rad = base(f, gain="gain_rad")
    add("units mismatched (m -> rad, factor 1)", "refuse", s_rad)
    add("units converted by a stated factor", "ok-factor", replace(s_rad, couplings=(replace(s_rad.couplings[0], factor=2.0),
                                                                                    replace(s_rad.couplings[1], factor=0.5))))
    add("duplicate connection to one input", "refuse", replace(s, couplings=(c0, c1, Coupling(("L1", "y"), ("L2", "u")))))
    add("self-loop", "refuse", replace(s, couplings=(c0, c1, Coupling(("L2", "y"), ("L2", "u")))))
    for bad in ("L1.y", ("L1",), ("L1", "y", "z"), None, 3, ("L1", 3)):
        add("malformed coupling end", "refuse", replace(s, couplings=(replace(c0, source=bad), c1)))
    for factor in (math.nan, math.inf, "abc", None):
        add("non-finite or non-numeric factor", "refuse", replace(s, couplings=(replace(c0, factor=factor), c1)))
    for x in NUMBERS:  # step sizes and stop times; "0.01" is read as the number
        step = {None: "ok", "0.01": "ok", 1e300: "ok-any"}.get(x, "refuse") if not isinstance(x, list) else "refuse"
        add("step size", step, s, step=x)
        stop = {None: "ok", "0.01": "ok-any", 1e-300: "ok-any"}.get(x, "refuse") if not isinstance(x, list) else "refuse"
        add("stop time", stop, s, stop=x)
    add("stop before start", "refuse", replace(s, start_time=0.2))
    add("stop at start", "refuse", s, stop=0.0)
    for key in ("tol", "coupling_tol", "min_step", "max_step", "max_iterations", "workers"):
        for x in (0, -1, math.nan, "x", 2.5 if key in ("max_iterations", "workers") else -0.5):
            add(f"setting {key}", "refuse", s, **{key: x}, **({"adaptive": True} if key in ("tol", "min_step", "max_step") else {}))
    add("min_step above max_step", "refuse", s, adaptive=True, min_step=0.05, max_step=0.01)
    for scheme, ext in (("bogus", "linear"), ("jacobi", "cubic"), ("newton", "spline"), (3, "hold")):
        add("unknown scheme or extrapolation", "refuse", s, scheme=scheme, extrapolation=ext)
    add("no FMUs", "refuse", replace(s, units=(), couplings=(), recorded=()))
    add("repeated FMU names", "refuse", replace(s, units=s.units[:2] + (replace(s.units[2], name="G"),)))
    add("Gauss-Seidel order naming an unknown FMU", "refuse", replace(s, order=("L1", "G", "X")))
    add("FMU file that does not exist", "refuse", replace(s, units=s.units[:2] + (replace(s.units[2], path=Path("none.fmu")),)))
    add("non-finite start value", "refuse", replace(s, units=(replace(s.units[0], start_values={"T": math.nan}),) + s.units[1:]))
    add("algebraic loop under jacobi", "refuse", replace(s, couplings=(c0, Coupling(("G", "y"), ("L1", "u"))),
                                                        units=(replace(s.units[0], path=f["gain"]),) + s.units[1:]),
        scheme="jacobi")
    # hostile FMUs: fmi2Error, fmi2Discard and NaN outputs after 0.035 s, no FMU states
    for which, cause in (("lag_nan", "non-finite"), ("lag_error", "fmu-failure"), ("lag_discard", "fmu-failure")):
        for scheme, ext, adaptive in (("jacobi", "hold", False), ("gauss-seidel", "linear", False),
                                      ("newton", "linear", False), ("gauss-seidel", "hold", True)):
            add(f"FMU returning {cause} ({which})", "fail:" + cause, base(f, lag2=which), scheme=scheme,
                extrapolation=ext, adaptive=adaptive, **({"tol": 1e-2} if adaptive else {}))
    for scheme, adaptive in (("newton", False), ("iterative", False), ("jacobi", True)):
        add("FMU without states under a scheme that needs them", "refuse", base(f, lag2="lag_nostate"),
            scheme=scheme, extrapolation="linear" if scheme != "jacobi" else "hold", adaptive=adaptive)
    # valid settings picked at random: they must run and match the closed form
    for _ in range(40):
        scheme = rng.choice(["jacobi", "gauss-seidel", "iterative", "newton"])
        ext = rng.choice(["hold", "linear"] + (["cubic"] if scheme in ("newton", "iterative") else []))
        kw = {"scheme": scheme, "extrapolation": ext, "step": rng.choice([0.01, 0.005, 0.0025]),
              "workers": rng.choice([1, 2])}
        if rng.random() < 0.3 and scheme != "jacobi":
            kw.update(adaptive=True, tol=1e-3)
        expected = "refuse" if ext == "cubic" else "ok"  # these FMUs give no output derivatives
        add("valid settings", expected, s, **kw)
    return out


class _Hang(Exception):
    pass


def classify(expected, system, kw, seconds=None):
    """(class, detail) of one case (``seconds``: a case still running after that long is a ``hang``; the
    command line's guard, for masters that loop for ever on a step below the time resolution)."""
    import signal

    if seconds:
        def alarm(*_):
            raise _Hang

        signal.signal(signal.SIGALRM, alarm)
        signal.alarm(seconds)
    try:
        r = run(system, estimate=False, **kw)
    except _Hang:
        return "hang", f"still running after {seconds} s"
    except CosimError as e:
        msg = str(e)
        if "\n" in msg:
            return "refused-multiline", msg
        return ("refused" if expected == "refuse" else "refused-unexpectedly"), msg
    except Exception as e:  # noqa: BLE001 - the battery counts what escapes
        return "crash", f"{type(e).__name__}: {e}"
    finally:
        if seconds:
            signal.alarm(0)
    if r.summary.status == "failed":
        want = expected.split(":", 1)[1] if expected.startswith("fail:") else None
        if want is not None and r.summary.failure.cause != want:
            return "failed-wrong-cause", str(r.summary.failure)
        if expected.startswith(("ok", "fail")) and not np.all(np.isfinite(r.values[:-1])):
            return "silent-wrong", "non-finite values before the failure"
        return ("failed" if want else "failed-unexpectedly"), str(r.summary.failure).splitlines()[0]
    if expected in ("refuse",) or expected.startswith("fail"):
        return "silent-wrong", f"ran {r.summary.status} where {expected} was expected"
    if not np.all(np.isfinite(r.values)):
        return "silent-wrong", "non-finite values in an ok run"
    if expected in ("ok-factor", "ok-any"):  # ran as asked; the closed form is another system's
        return "ok", ""
    tol = 0.1 if expected == "ok-coarse" else 0.06  # first order at 10 ms: 3e-2 of the signal
    err = abs(r["L2.y"][-1] - exact_l2(r.time[-1])) / (A + B)
    if not err < tol:
        return "silent-wrong", f"L2.y off the closed form by {err:.3g} of its range"
    return "ok", ""


def battery(folder: Path, seed: int = 27, seconds=None):
    """(Counter of classes, [(kind, class, detail)])."""
    f = build(folder)
    rows = [(kind, *classify(expected, system, kw, seconds)) for kind, expected, system, kw in cases(f, seed)]
    return Counter(cls for _, cls, _ in rows), rows


def test_hostile_systems_are_refused_in_one_line_or_run_with_a_clear_status(tmp_path):
    counts, rows = battery(tmp_path)
    bad = [r for r in rows if r[1] not in ("refused", "failed", "ok")]
    assert not bad, bad[:10]
    assert counts["refused"] > 100 and counts["failed"] == 12 and counts["ok"] > 30, counts
    # the refusals name what is wrong
    said = {kind: detail for kind, cls, detail in rows if cls == "refused"}
    assert "units differ (m -> rad)" in said["units mismatched (m -> rad, factor 1)"]
    assert "is driven twice" in said["duplicate connection to one input"]
    assert "connects an FMU to itself" in said["self-loop"]
    assert "algebraic loop through FMUs" in said["algebraic loop under jacobi"]
    assert "couplings need Real" in said["type mismatch Real/Integer"]
    nan = [d for kind, cls, d in rows if kind.startswith("FMU returning non-finite")]
    assert all("FMU 'L2' returned nan for output 'y'" in d for d in nan), nan


def test_two_names_of_one_unit_are_one_unit():
    """physical_units.mismatch against the FMUs' <UnitDefinitions> (FMI 2.0 section 2.2.2)."""
    from types import SimpleNamespace as NS

    from fmugen.cosim.physical_units import mismatch

    def md(*defs):
        return NS(unitDefinitions=[NS(name=n, baseUnit=NS(kg=kg, m=m, s=-2, A=0, K=0, mol=0, cd=0, rad=0,
                                                         factor=f, offset=0.0)) for n, kg, m, f in defs])

    torque = md(("N.m", 1, 2, 1.0), ("J", 1, 2, 1.0), ("kN.m", 1, 2, 1e3))
    var = lambda u: NS(unit=u, declaredType=None)  # noqa: E731
    assert mismatch(torque, var("N.m"), torque, var("J"), 1.0) is None
    assert mismatch(torque, var("N.m"), torque, var("kN.m"), 1.0) == ("units differ (N.m -> kN.m) and the coupling "
                                                                     "states no conversion factor")
    assert mismatch(torque, var("N.m"), torque, var("kN.m"), 1e-3) is None  # a stated conversion
    assert mismatch(md(), var("m"), md(), var(""), 1.0) is None  # one side without a unit
    assert mismatch(md(), var("m"), md(), NS(unit=None, declaredType=NS(unit="rad")), 1.0) is not None


if __name__ == "__main__":  # python tests/test_cosim_hostile.py: the counts per class and per kind
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        counts, rows = battery(Path(tmp), int(sys.argv[1]) if len(sys.argv) > 1 else 27, seconds=30)
    print(f"{len(rows)} cases: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    per = Counter((kind, cls) for kind, cls, _ in rows)
    for (kind, cls), n in sorted(per.items()):
        print(f"  {kind:55s} {cls:22s} {n}")
    for kind, cls, detail in rows:
        if cls not in ("refused", "failed", "ok"):
            print("BAD", kind, cls, detail[:300])
