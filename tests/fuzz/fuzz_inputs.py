"""Seeded fuzzing of what users hand fmugen (issue 19): scene files, ``--set``
values, sweep grids, and the co-simulation master with misbehaving FMUs.

The contract checked for every case: the call either succeeds or raises
:class:`fmugen.errors.FmugenError` (a one-line message, exit 2 on the command
line) within :data:`CASE_SECONDS`.  Anything else -- another exception
(a traceback for the user), or a case that takes longer -- is a *finding*,
printed with its seed and case number so that it reproduces.

* scenes: a shipped scene's text mutated (a literal replaced by a hostile
  value, a line deleted or doubled, the file cut short, bytes inserted,
  nesting 3000 deep), then ``load_scene``;
* ``--set``: a scene loaded with one or two ``NAME=VALUE`` overrides, names
  from the scene or made up, values hostile or random;
* sweep grids: ``parse_grid``/``parse_samples``/``make_points`` with
  mutated specifications, counts up to 10^7 values a grid (the sweep must
  count its points and refuse more than a million before making any);
* master: two coupled third-party FMUs (``tests/third_party_fmu.py``), one of
  them broken or stateless, under random schemes, extrapolations, steps and
  adaptivity.

Short run (in the suite): ``tests/fuzz/test_fuzz_inputs.py``.  Long run:
``python tests/fuzz/fuzz_inputs.py --cases 2000 --seed 1`` (prints the counts).
"""
from __future__ import annotations

import argparse
import random
import re
import sys
import tempfile
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
SCENE = ROOT / "examples" / "scenes" / "single_joint_split.toml"
CASE_SECONDS = 30.0

HOSTILE = ["nan", "inf", "-inf", "1e400", "-1e400", "0", "-0.0", "1" + "0" * 400, "-1", "1e-320", '"text"',
           '"nan"', "[]", "{}", "true", "[1, 2]", '"' + "x" * 5000 + '"', '"\\u0000"', '"a.b"', "-9" * 50,
           "0x10", "1_000", '"1/0"', '"m1/k"', "2024-01-01"]
NAMES = ["joint.J", "joint.B_m", "actuator.V_t", "actuator.beta_e", "valve.omega_v", "path.q_end",
         "path.qd_max", "amp.K_p", "scene.stop", "scene.step", "scene.start", "scene.tolerance",
         "fmus.chain.solver", "fmus.joint.solver", "cosim.scheme", "nosuch.x", "joint", "", ".", "joint.",
         "joint.J.x", "scene", "instances.joint.type"]


#: mutations a run can leave out (``pending``) while their fixes are not in the tree: "huge-int"
#: (integers above the double range), "deep" (nesting 3000 deep); both are fixed, none is left out
PENDING = frozenset()


def _hostile(rng: random.Random, pending=frozenset()) -> str:
    v = rng.choice(HOSTILE)
    while "huge-int" in pending and re.fullmatch(r"-?[0-9]{300,}|(-9){50}", v):
        v = rng.choice(HOSTILE)
    return v


def _scene_case(rng: random.Random, text: str, pending=frozenset()) -> str:
    lines = text.splitlines()
    kind = rng.randrange(7)
    if kind == 0:  # a literal replaced
        idx = [i for i, l in enumerate(lines) if re.search(r"=\s*[-0-9.\"\[]", l) and not l.lstrip().startswith("#")]
        i = rng.choice(idx)
        lit = list(re.finditer(r"-?[0-9][0-9.eE+-]*|\"[^\"]*\"", lines[i]))
        if lit:
            m = rng.choice(lit)
            lines[i] = lines[i][:m.start()] + _hostile(rng, pending) + lines[i][m.end():]
    elif kind == 1:
        del lines[rng.randrange(len(lines))]
    elif kind == 2:
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
    elif kind == 3:
        return text[:rng.randrange(len(text))]
    elif kind == 4:
        pos = rng.randrange(len(text))
        junk = "".join(chr(rng.choice([0, 7, 10, 34, 39, 91, 93, 123, 125, 61, 0x2028, 0xFEFF, 0xE9]))
                       for _ in range(rng.randrange(1, 6)))
        return text[:pos] + junk + text[pos:]
    elif kind == 5:
        depth = rng.choice([50, 200] if "deep" in pending else [50, 1000, 3000])
        lines.insert(rng.randrange(len(lines)), "deep = " + "[" * depth + "]" * depth)
    else:  # a key's value becomes a table or an array
        i = rng.randrange(len(lines))
        if "=" in lines[i]:
            k = lines[i].split("=", 1)[0]
            lines[i] = k + "= " + rng.choice(["{ a = 1 }", "[1, [2]]", '"', "=", "1 2"])
    return "\n".join(lines) + "\n"


def _value(rng: random.Random, pending=frozenset()) -> str:
    r = rng.random()
    if r < 0.5:
        return _hostile(rng, pending).strip('"')
    if r < 0.8:
        return f"{rng.choice([-1, 1]) * rng.random():.6f}e{rng.randrange(-330, 330)}"
    return rng.choice(["rodas3", "dopri5", "rk4", "newton", "1,2", "a", " ", "1e", "--", "=1"])


def _grid_spec(rng: random.Random, max_points: int) -> list:
    items = []
    budget = max_points
    valid = ["joint.J", "joint.B_m", "actuator.V_t", "actuator.beta_e", "valve.omega_v", "path.q_end"]
    for _ in range(rng.randrange(1, 4)):
        name = rng.choice(valid) if rng.random() < 0.85 else rng.choice(NAMES)
        r = rng.random()
        if r < 0.3:
            n = rng.choice([0, 1, 2, 10, 1000, rng.randrange(0, min(budget, 10 ** 6) + 2), 10 ** 6, 10 ** 7])
            budget = max(1, budget // max(n, 1))
            a, b = (_value(rng), _value(rng)) if rng.random() < 0.5 else (f"{rng.uniform(0.1, 2):g}",
                                                                           f"{rng.uniform(2, 5):g}")
            spec = f"{rng.choice(['linspace', 'geomspace'])}({a},{b},{n})"
        elif r < 0.45:
            spec = ",".join(_value(rng) for _ in range(rng.randrange(0, 5)))
        elif r < 0.6:
            spec = ",".join(f"{rng.uniform(0.1, 10):.4g}" for _ in range(rng.randrange(1, 6)))
        else:
            spec = rng.choice(["1,2,4", "linspace(1,2)", "geomspace(0,1,3)", "linspace(1,2,1e3)", "1,,2",
                               "normal(1,0.1)", "uniform(0,1)", "linspace(nan,1,3)", "geomspace(-1,-2,3)"])
        items.append(f"{name}={spec}" if rng.random() < 0.95 else spec)
    return items


def _sample_spec(rng: random.Random) -> list:
    dist = rng.choice(["normal", "uniform", "lognormal", "bogus", ""])
    if rng.random() < 0.5:
        return [f"{rng.choice(['joint.J', 'actuator.beta_e'])}={rng.choice(['normal', 'uniform'])}(1,{rng.random():.3g})"]
    args = ",".join(_value(rng) for _ in range(rng.randrange(0, 4)))
    return [f"{rng.choice(NAMES)}={dist}({args})"]


class Runner:
    def __init__(self, seed: int, workdir: Path, max_points: int = 10 ** 5, pending=frozenset()):
        self.pending = frozenset(pending)
        self.rng = random.Random(seed)
        self.seed = seed
        self.dir = workdir
        self.max_points = max_points
        self.counts = {"scene": 0, "set": 0, "grid": 0, "master": 0}
        self.accepted = dict.fromkeys(self.counts, 0)
        self.findings = []
        self._lag = self._broken = None

    def _check(self, kind: str, n: int, what: str, call) -> None:
        from fmugen.errors import FmugenError

        self.counts[kind] += 1
        t0 = time.perf_counter()
        try:
            call()
            self.accepted[kind] += 1
        except FmugenError as e:
            if "\n" in str(e).strip() and kind != "scene":
                self.findings.append(f"{kind} #{n} (seed {self.seed}): a message of several lines for {what}: "
                                     f"{str(e)[:200]!r}")
        except RecursionError:
            self.findings.append(f"{kind} #{n} (seed {self.seed}): RecursionError for {what}")
        except Exception as e:  # noqa: BLE001 - any other exception is a finding
            tb = traceback.format_exc(limit=3).strip().splitlines()[-1]
            self.findings.append(f"{kind} #{n} (seed {self.seed}): {type(e).__name__} for {what}: {tb[:300]}")
        dt = time.perf_counter() - t0
        if dt > CASE_SECONDS:
            self.findings.append(f"{kind} #{n} (seed {self.seed}): took {dt:.0f} s for {what}")

    # -- the four surfaces --------------------------------------------------------
    def scene(self, n: int) -> None:
        from fmugen.scene import load_scene

        text = _scene_case(self.rng, SCENE.read_text(), self.pending)
        path = self.dir / f"scene_{n}.toml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        self._check("scene", n, f"a mutated scene ({path.name})", lambda: load_scene(path))

    def set(self, n: int) -> None:
        from fmugen.scene import load_scene

        sets = [f"{self.rng.choice(NAMES)}={_value(self.rng, self.pending)}" for _ in range(self.rng.randrange(1, 3))]
        if self.rng.random() < 0.2:
            odd = [float("nan"), -1, True, None, "x", [1]] + ([] if "huge-int" in self.pending else [10 ** 400])
            sets = {self.rng.choice(NAMES): self.rng.choice(odd)}
        self._check("set", n, f"--set {sets!r}", lambda: load_scene(SCENE, set=sets))

    def grid(self, n: int) -> None:
        from fmugen.sweep.points import make_points, parse_grid, parse_samples

        grid = _grid_spec(self.rng, self.max_points) if self.rng.random() < 0.8 else []
        samples = _sample_spec(self.rng) if self.rng.random() < 0.4 else []
        sizes = self.rng.choice([None, 0, 1, 5, 5, 20, -1, 2.5, True, 10 ** 9])
        seed = self.rng.choice([None, 0, 1, 1, -3, 2 ** 70])
        if not samples and self.rng.random() < 0.8:
            sizes = seed = None  # a plain grid, as most sweeps are

        def call():
            g, s = parse_grid(grid), parse_samples(samples)
            make_points(g, s, n=sizes, seed=seed)  # counts its points before making one

        self._check("grid", n, f"--grid {grid!r} --sample {samples!r} -n {sizes!r} --seed {seed!r}", call)

    def master(self, n: int) -> None:
        sys.path.insert(0, str(HERE.parent))
        from third_party_fmu import broken_fmus, build_lag

        from fmugen.cosim import run
        from fmugen.cosim.system import Coupling, CosimSystem, Recorded, Unit

        if self._lag is None:
            d = self.dir / "fmus"
            d.mkdir(exist_ok=True)
            self._lag = build_lag(d)
            self._broken = broken_fmus(d, self._lag, huge=False)
        rng = self.rng
        other = self._lag if rng.random() < 0.4 else self._broken[rng.choice(sorted(self._broken))]
        scheme = rng.choice(["jacobi", "gauss-seidel", "iterative", "newton", "bogus"])
        ext = rng.choice(["hold", "linear", "quadratic", "cubic", "nope"])
        step = rng.choice([1e-4, 1e-3, 0.01, 0.05, 1.0, 0.0, -1.0, float("nan"), 1e300])
        stop = rng.choice([0.05, 0.1, 0.0, -1.0, float("inf")])
        adaptive = rng.random() < 0.3
        start = {"T": rng.choice([0.1, 0.0, -0.1, 1e-300, float("nan")]), "u": rng.choice([1.0, 1e308])}
        system = CosimSystem(name="lags", units=(Unit("A", self._lag, "cs", start), Unit("B", other, "cs")),
                             couplings=(Coupling(("A", "y"), ("B", "u")),),
                             recorded=(Recorded("A.y", "A", "y"), Recorded("B.y", "B", "y")),
                             start_time=0.0, stop_time=0.1, step=0.01)
        what = f"B = {Path(other).name}, {scheme}/{ext}, step {step}, stop {stop}, adaptive {adaptive}, A {start}"

        def call():
            run(system, scheme=scheme, extrapolation=ext, step=step, stop=stop, adaptive=adaptive)

        self._check("master", n, what, call)

    def run(self, cases: int, kinds=("scene", "set", "grid", "master")) -> None:
        for n in range(cases):
            getattr(self, kinds[n % len(kinds)])(n)

    def report(self) -> str:
        parts = ", ".join(f"{k} {self.counts[k]} ({self.accepted[k]} accepted)" for k in self.counts)
        return f"seed {self.seed}: {sum(self.counts.values())} cases: {parts}; {len(self.findings)} findings"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=400)
    ap.add_argument("--seed", type=int, default=20261202)
    ap.add_argument("--max-points", type=int, default=10 ** 6)
    ap.add_argument("--keep", metavar="DIR", help="write the cases' files (scenes, FMUs) into DIR and keep them")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="fmugen_fuzz_") as d:
        if args.keep:
            Path(args.keep).mkdir(parents=True, exist_ok=True)
        r = Runner(args.seed, Path(args.keep or d), args.max_points)
        r.run(args.cases)
        for f in r.findings:
            print("FINDING", f)
        print(r.report())
    return 1 if r.findings else 0


if __name__ == "__main__":
    sys.exit(main())
