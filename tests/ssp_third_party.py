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
what most third-party FMUs give.  The system is linear: x' = A x with the exact solution expm(A t) x0,
an independent reference.
"""
from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path

import numpy as np

# the spring's fast mode (about 245 rad/s) is damped within ~20 ms; the drive f0 then moves both masses
M_A, C_A, M_B, C_B, K, F0, W = 1.0, 150.0, 2.0, 300.0, 4.0e4, 100.0, 20.0
X0 = (0.0, 0.0, 0.0, 0.0)  # xa, va, F, v2: at rest; the drive f0 starts at t = 0

C_SOURCE = r"""
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

/* value references: A: 0 x, 1 v, 2 m, 3 c, 4 F (in), 5 f0;  B: 0 F, 1 v2, 2 m2, 3 c2, 4 v_in, 7 k */
#define NR 9
#define NY 4
typedef struct { double r[NR]; double y[NY]; double time; fmi2CallbackFunctions cb; } Comp;

static void rhs(const Comp *c, const double *y, double *dy) {
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

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Comp *c = calloc(1, sizeof(Comp));
    if (!c) return NULL;
    c->cb = *cb;
#ifdef SPRING
    c->r[0] = FB0; c->r[2] = MB; c->r[3] = CB; c->r[7] = KK;
#else
    c->r[0] = XA0; c->r[2] = MA; c->r[3] = CA; c->r[5] = F0;
#endif
    return c;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean td, fmi2Real tol, fmi2Real t0, fmi2Boolean sd,
                               fmi2Real t1) { ((Comp *)c)->time = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { return fmi2Error; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Comp *s = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= NR) return fmi2Error;
        v[i] = s->r[vr[i]];
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Comp *s = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= NR) return fmi2Error;
        s->r[vr[i]] = v[i];
    }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { return n ? fmi2Error : fmi2OK; }

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *st) {
    Comp *copy = *st ? (Comp *)*st : malloc(sizeof(Comp));
    if (!copy) return fmi2Error;
    memcpy(copy, c, sizeof(Comp));
    *st = copy;
    return fmi2OK;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate st) {
    if (!st) return fmi2Error;
    memcpy(c, st, sizeof(Comp));
    return fmi2OK;
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *st) { free(*st); *st = NULL; return fmi2OK; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate st, size_t *n) { return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate st, fmi2Byte b[], size_t n) { return fmi2Error; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *st) { return fmi2Error; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[],
                                        fmi2Real dz[]) { return fmi2Error; }
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer o[], const fmi2Real v[]) { return fmi2Error; }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer o[], fmi2Real v[]) { return fmi2Error; }

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSet) {
    Comp *s = c;
    if (!(h > 0)) return fmi2Error;
    int n = (int)ceil(h / 1e-5 - 1e-9);
    double dt = h / n, y[NY], k1[NY], k2[NY], k3[NY], k4[NY], tmp[NY];
    memcpy(y, s->y, sizeof y);
    y[0] = s->r[0]; y[1] = s->r[1];
    for (int i = 0; i < n; i++) {
        rhs(s, y, k1);
        for (int j = 0; j < NY; j++) tmp[j] = y[j] + 0.5 * dt * k1[j];
        rhs(s, tmp, k2);
        for (int j = 0; j < NY; j++) tmp[j] = y[j] + 0.5 * dt * k2[j];
        rhs(s, tmp, k3);
        for (int j = 0; j < NY; j++) tmp[j] = y[j] + dt * k3[j];
        rhs(s, tmp, k4);
        for (int j = 0; j < NY; j++) y[j] += dt / 6 * (k1[j] + 2 * k2[j] + 2 * k3[j] + k4[j]);
    }
    for (int j = 0; j < NY; j++) if (!isfinite(y[j])) return fmi2Error;
    memcpy(s->y, y, sizeof y);
    s->r[0] = y[0]; s->r[1] = y[1];
    s->time = t + h;
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) { return fmi2Error; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    if (k != fmi2LastSuccessfulTime) return fmi2Error;
    *v = ((Comp *)c)->time;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) { return fmi2Error; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) { return fmi2Error; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) { return fmi2Error; }
"""


def _xml(ident: str, guid: str, variables: list, outputs: list, initial_unknowns: list, fmi_version="2.0") -> str:
    sv = []
    for name, vr, caus, var, init, start, unit in variables:
        attrs = f'name="{name}" valueReference="{vr}" causality="{caus}" variability="{var}"'
        if init:
            attrs += f' initial="{init}"'
        real = "<Real" + (f' unit="{unit}"' if unit else "") + (f' start="{start!r}"' if start is not None else "") + "/>"
        sv.append(f"    <ScalarVariable {attrs}>{real}</ScalarVariable>")
    units = sorted({v[6] for v in variables if v[6]})
    ud = "".join(f'<Unit name="{u}"/>' for u in units)
    outs = "".join(f'<Unknown index="{i}"/>' for i in outputs)
    iu = "".join(f'<Unknown index="{i}" dependencies="{d}"/>' for i, d in initial_unknowns)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="{fmi_version}" modelName="{ident}" guid="{guid}" generationTool="hand-written C (test)"
    variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true"
      canGetAndSetFMUstate="true" canSerializeFMUstate="false" providesDirectionalDerivative="false"/>
  <UnitDefinitions>{ud}</UnitDefinitions>
  <ModelVariables>
{chr(10).join(sv)}
  </ModelVariables>
  <ModelStructure><Outputs>{outs}</Outputs>{f"<InitialUnknowns>{iu}</InitialUnknowns>" if iu else ""}</ModelStructure>
</fmiModelDescription>
"""


def build_fmus(folder: Path, fmi_version: str = "2.0") -> dict:
    """Compile the two FMUs into ``folder`` (mass.fmu, spring.fmu); returns their paths."""
    from fmugen.fmi.build import fmi_headers_dir, platform_binary

    platform, suffix = platform_binary()
    folder.mkdir(parents=True, exist_ok=True)
    src = folder / "third_party.c"
    src.write_text(C_SOURCE)
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
    out = {}
    for ident, flags in defs.items():
        lib = folder / f"{ident}{suffix}"
        subprocess.run(["cc", "-O2", "-shared", "-fPIC", "-std=c99", f"-I{fmi_headers_dir()}", *flags, "-o", str(lib),
                        str(src), "-lm"], check=True, capture_output=True)
        variables, outputs, iu = mv[ident]
        xml = _xml(ident, f"{{third-party-{ident}}}", variables, outputs, iu, fmi_version)
        fmu = folder / f"{ident}.fmu"
        with zipfile.ZipFile(fmu, "w") as zf:
            zf.writestr("modelDescription.xml", xml)
            zf.write(lib, f"binaries/{platform}/{ident}{suffix}")
        out[ident] = fmu
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
