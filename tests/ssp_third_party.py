"""Third-party FMUs for the SSP import tests, made here from C sources this file writes (no binaries,
no code from elsewhere): a hand-written FMI 2.0 Co-Simulation FMU, as another tool would ship it.

Two masses, each in its own FMU, joined by a stiff spring whose force is a state of the second FMU
(no direct feedthrough on either side, like the actuator chain and the joint of fmugen's split rig):

* ``mass`` (A): x' = v, m v' = F + f - c v, the drive f rising smoothly to f0 (f'' = W^2 (f0 - f) - 2 W f');
  input F [N]; outputs x [m], v [m/s];
* ``spring`` (B): F' = k (v2 - va), m2 v2' = -F - c2 v2 with va = v_in / 1000 (its input is in mm/s:
  the SSP states the conversion as a LinearTransformation, factor 1000); input v_in [mm/s];
  outputs F [N] and v2 [m/s].

Each FMU integrates with classical RK4 on sub-steps of at most 1e-5 s, gets and sets its state, and
has no directional derivatives, input interpolation or output derivatives -- the master must do with
what most third-party FMUs give (the FMI part: ``third_party_fmu.rk4_source``).  The system is linear: x' = A x with the exact solution expm(A t) x0,
an independent reference.
"""
from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from third_party_fmu import compile_fmu, model_description, rk4_source

# the spring's fast mode (about 245 rad/s) is damped within ~20 ms; the drive f0 then moves both masses
M_A, C_A, M_B, C_B, K, F0, W = 1.0, 150.0, 2.0, 300.0, 4.0e4, 100.0, 20.0
X0 = (0.0, 0.0, 0.0, 0.0)  # xa, va, F, v2: at rest; the drive f0 starts at t = 0

# value references: A: 0 x, 1 v, 2 m, 3 c, 4 F (in), 5 f0;  B: 0 F, 1 v2, 2 m2, 3 c2, 4 v_in, 7 k
NR, NY = 9, 4
MODEL_C = r"""
static void start(Comp *c) {
#ifdef SPRING
    c->r[0] = FB0; c->r[2] = MB; c->r[3] = CB; c->r[7] = KK;
#else
    c->r[0] = XA0; c->r[2] = MA; c->r[3] = CA; c->r[5] = F0;
#endif
}

static void rhs(const Comp *c, double t, const double *y, double *dy) {
    (void)t;
#ifdef SPRING
    dy[0] = c->r[7] * (y[1] - c->r[4] / 1000.0);
    dy[1] = (-y[0] - c->r[3] * y[1]) / c->r[2];
#else
    dy[0] = y[1];
    dy[1] = (c->r[4] + y[2] - c->r[3] * y[1]) / c->r[2];
    dy[2] = y[3];  /* the drive f: f0 through a critically damped filter (rate W), smooth from rest */
    dy[3] = W * W * (c->r[5] - y[2]) - 2 * W * y[3];
#endif
}

/* the outputs r[0], r[1] are the first two states */
static void load(Comp *c, double *y) { y[0] = c->r[0]; y[1] = c->r[1]; }
static void store(Comp *c, const double *y) { c->r[0] = y[0]; c->r[1] = y[1]; }
static void outputs(Comp *c) { (void)c; }
"""


def build_fmus(folder: Path, fmi_version: str = "2.0") -> dict:
    """Compile the two FMUs into ``folder`` (mass.fmu, spring.fmu); returns their paths."""
    defs = {"mass": ["-DXA0=%r" % X0[0], "-DMA=%r" % M_A, "-DCA=%r" % C_A, "-DF0=%r" % F0, "-DW=%r" % W],
            "spring": ["-DSPRING", "-DFB0=%r" % X0[2], "-DMB=%r" % M_B, "-DCB=%r" % C_B, "-DKK=%r" % K]}
    mv = {
        "mass": ([("x", 0, "output", "continuous", "exact", X0[0], "m"), ("v", 1, "output", "continuous", "exact",
                                                                         X0[1], "m/s"),
                  ("m", 2, "parameter", "fixed", "exact", M_A, "kg"), ("c", 3, "parameter", "fixed", "exact", C_A,
                                                                       "N.s/m"),
                  ("F", 4, "input", "continuous", None, 0.0, "N"),
                  ("f0", 5, "parameter", "fixed", "exact", F0, "N")], [1, 2], []),
        "spring": ([("F", 0, "output", "continuous", "exact", X0[2], "N"),
                    ("v2", 1, "output", "continuous", "exact", X0[3], "m/s"),
                    ("m", 2, "parameter", "fixed", "exact", M_B, "kg"),
                    ("c", 3, "parameter", "fixed", "exact", C_B, "N.s/m"),
                    ("v_in", 4, "input", "continuous", None, 0.0, "mm/s"),
                    ("k", 7, "parameter", "fixed", "exact", K, "N/m")], [1, 2], []),
    }
    source = rk4_source(NR, NY, MODEL_C)
    out = {}
    for ident, flags in defs.items():
        variables, outputs, iu = mv[ident]
        # the outputs are states: no direct feedthrough (FMI 2.0: dependencies="" depends on no input;
        # no attribute at all would mean "on every input", an algebraic loop through both FMUs)
        xml = model_description(ident, f"{{third-party-{ident}}}", variables, [(i, "") for i in outputs], iu,
                                fmi_version)
        out[ident] = compile_fmu(folder, ident, source, xml, ["-O2", "-std=c99", *flags],
                                 source_name="third_party.c")
    return out


SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="two_masses">
  <ssd:System name="two_masses">
    <ssd:Elements>
      <ssd:Component name="A" source="resources/mass.fmu">
        <ssd:Connectors>
          <ssd:Connector name="x" kind="output"><ssc:Real unit="m"/></ssd:Connector>
          <ssd:Connector name="v" kind="output"><ssc:Real unit="m/s"/></ssd:Connector>
          <ssd:Connector name="F" kind="input"><ssc:Real unit="N"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="A">
                <ssv:Parameters>
                  <ssv:Parameter name="m"><ssv:Real value="{m_a!r}"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="B" source="resources/spring.fmu">
        <ssd:Connectors>
          <ssd:Connector name="v_in" kind="input"><ssc:Real unit="mm/s"/></ssd:Connector>
          <ssd:Connector name="F" kind="output"><ssc:Real unit="N"/></ssd:Connector>
          <ssd:Connector name="v2" kind="output"><ssc:Real unit="m/s"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding source="resources/B.ssv"/>
        </ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="A" startConnector="v" endElement="B" endConnector="v_in">
        <ssc:LinearTransformation factor="1000"/>
      </ssd:Connection>
      <ssd:Connection startElement="B" startConnector="F" endElement="A" endConnector="F"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="{stop!r}"/>
</ssd:SystemStructureDescription>
"""

SSV = """<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="B">
  <ssv:Parameters>
    <ssv:Parameter name="k"><ssv:Real value="{k!r}"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>
"""


def write_ssp(path: Path, fmus: dict, m_a: float = M_A, k: float = K, stop: float = 0.5, ssd: str = None) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("SystemStructure.ssd", ssd or SSD.format(m_a=m_a, stop=stop))
        zf.writestr("resources/B.ssv", SSV.format(k=k))
        zf.write(fmus["mass"], "resources/mass.fmu")
        zf.write(fmus["spring"], "resources/spring.fmu")
    return path


def exact(times, m_a: float = M_A, k: float = K) -> dict:
    """The linear system's solution by the matrix exponential: xa, va, xb, vb and F at ``times``."""
    import scipy.linalg as sl

    # states xa, va, F, v2, f, f' and a constant 1: xa' = va, m_a va' = F + f - c_a va,
    # F' = k (v2 - va), m_b v2' = -F - c_b v2, f'' = W^2 (f0 - f) - 2 W f'
    A = np.array([[0, 1, 0, 0, 0, 0, 0],
                  [0, -C_A / m_a, 1 / m_a, 0, 1 / m_a, 0, 0],
                  [0, -k, 0, k, 0, 0, 0],
                  [0, 0, -1 / M_B, -C_B / M_B, 0, 0, 0],
                  [0, 0, 0, 0, 0, 1, 0],
                  [0, 0, 0, 0, -W * W, -2 * W, W * W * F0],
                  [0, 0, 0, 0, 0, 0, 0]], dtype=float)
    x0 = np.array(list(X0) + [0.0, 0.0, 1.0])
    xs = np.array([sl.expm(A * t) @ x0 for t in times])
    return {"A.x": xs[:, 0], "A.v": xs[:, 1], "B.F": xs[:, 2], "B.v2": xs[:, 3]}


SSD_SPRING_ONLY = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0" name="supplier">
  <ssd:System name="supplier">
    <ssd:Elements>
      <ssd:Component name="B" source="resources/spring.fmu">
        <ssd:Connectors>
          <ssd:Connector name="v_in" kind="input"><ssc:Real unit="mm/s"/></ssd:Connector>
          <ssd:Connector name="F" kind="output"><ssc:Real unit="N"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding source="resources/B.ssv"/></ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
</ssd:SystemStructureDescription>
"""
