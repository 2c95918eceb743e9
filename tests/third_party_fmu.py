"""A third-party FMI 2.0 Co-Simulation FMU written from C here, not by fmugen.

``lag``: a first-order lag T y' = u - y stepped exactly over each
communication step with the input held (y <- u + (y - u) exp(-h/T)), one
input ``u``, one output ``y``, a parameter ``T``.  Its modelDescription
declares ``canGetAndSetFMUstate="false"`` and its fmi2GetFMUstate refuses,
as many exported tool FMUs do.  :func:`build_lag` compiles it; :func:`broken_fmus`
writes the broken variants the master must name in one line.

The FMI 2.0 part every hand-written test FMU shares, written once here (used by
``tests/feedthrough_fmu.py`` and ``tests/ssp_third_party.py`` too):

* :func:`rk4_source`: the C of a Co-Simulation FMU around a model the caller
  writes (its states, equations and outputs), integrated by classical RK4 on
  sub-steps of at most 1e-5 s, with its state got and set, and no directional
  or output derivatives;
* :func:`model_description`: its modelDescription.xml from a list of variables;
* :func:`compile_fmu`: the shared library compiled with the system's C
  compiler and zipped with its description.
"""
from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path

import fmpy

FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"

LAG_C = r"""
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

typedef struct { double y, u, T, t; fmi2CallbackFunctions cb; } Lag;

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    (void)name; (void)loc; (void)vis; (void)log;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, "{lag-0001}") != 0) return NULL;
    Lag *l = calloc(1, sizeof *l);
    l->T = 0.1; l->cb = *cb;
    return l;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean a, size_t n, const fmi2String s[]) {
    (void)c; (void)a; (void)n; (void)s; return fmi2OK; }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t0, fmi2Boolean d,
                               fmi2Real e) { (void)a; (void)b; (void)d; (void)e; ((Lag *)c)->t = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Lag *l = c;
    for (size_t i = 0; i < n; i++) v[i] = vr[i] == 0 ? l->y : vr[i] == 1 ? l->u : l->T;
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Lag *l = c;
    for (size_t i = 0; i < n; i++) { if (vr[i] == 1) l->u = v[i]; else if (vr[i] == 2) l->T = v[i]; else return fmi2Error; }
    return fmi2OK;
}
#define NONE(name, args) fmi2Status name args { return fmi2Error; }
NONE(fmi2GetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]))
NONE(fmi2GetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]))
NONE(fmi2GetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]))
NONE(fmi2SetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]))
NONE(fmi2SetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]))
NONE(fmi2SetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]))
NONE(fmi2GetFMUstate, (fmi2Component c, fmi2FMUstate *s))
NONE(fmi2SetFMUstate, (fmi2Component c, fmi2FMUstate s))
NONE(fmi2FreeFMUstate, (fmi2Component c, fmi2FMUstate *s))
NONE(fmi2SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate s, size_t *n))
NONE(fmi2SerializeFMUstate, (fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n))
NONE(fmi2DeSerializeFMUstate, (fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s))
NONE(fmi2GetDirectionalDerivative, (fmi2Component c, const fmi2ValueReference a[], size_t na,
     const fmi2ValueReference b[], size_t nb, const fmi2Real d[], fmi2Real e[]))
NONE(fmi2SetRealInputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
     const fmi2Integer o[], const fmi2Real v[]))
NONE(fmi2GetRealOutputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
     const fmi2Integer o[], fmi2Real v[]))
NONE(fmi2CancelStep, (fmi2Component c))
NONE(fmi2GetStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Status *v))
NONE(fmi2GetRealStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Real *v))
NONE(fmi2GetIntegerStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Integer *v))
NONE(fmi2GetBooleanStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v))
NONE(fmi2GetStringStatus, (fmi2Component c, const fmi2StatusKind s, fmi2String *v))
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean nos) {
    Lag *l = c; (void)nos;
    l->y = l->u + (l->y - l->u) * exp(-h / l->T);
    l->t = t + h;
    return fmi2OK;
}
"""

LAG_XML = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="{version}" modelName="lag" guid="{{lag-0001}}" generationTool="a test"
  numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{ident}" canGetAndSetFMUstate="false" canSerializeFMUstate="false"
    canHandleVariableCommunicationStepSize="true"/>
  <ModelVariables>
    <ScalarVariable name="y" valueReference="0" causality="output" variability="continuous" initial="exact">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="u" valueReference="1" causality="input" variability="continuous"><Real start="0"/>
    </ScalarVariable>
    <ScalarVariable name="T" valueReference="2" causality="parameter" variability="fixed" initial="exact">
      <Real start="0.1"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1"/></Outputs></ModelStructure>
</fmiModelDescription>
"""


def _zip(path: Path, files: dict) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return path


def build_lag(d: Path) -> Path:
    """The ``lag`` FMU, compiled here with the system's C compiler."""
    return compile_fmu(d, "lag", LAG_C, LAG_XML.format(version="2.0", ident="lag"), cflags=["-O1"])


def broken_fmus(d: Path, lag: Path, huge: bool = True) -> dict:
    """{kind: path} of FMUs that cannot run, each for one reason (``huge``: with the 300 MB one)."""
    binary = f"binaries/{fmpy.platform}/lag{fmpy.sharedLibraryExtension}"
    with zipfile.ZipFile(lag) as z:
        lib = z.read(binary)
    good_xml = LAG_XML.format(version="2.0", ident="lag")
    out = {}
    (d / "empty.fmu").write_bytes(b"")
    out["empty"] = d / "empty.fmu"
    (d / "text.fmu").write_text("this is not a zip file\n")
    out["not a zip"] = d / "text.fmu"
    out["bad XML"] = _zip(d / "badxml.fmu", {"modelDescription.xml": good_xml[:300], binary: lib})
    out["FMI 1.0"] = _zip(d / "fmi1.fmu", {"modelDescription.xml": good_xml.replace('fmiVersion="2.0"',
                                                                                   'fmiVersion="1.0"'),
                                           binary: lib})
    out["no binary"] = _zip(d / "nobin.fmu", {"modelDescription.xml": good_xml,
                                              "binaries/win64/lag.dll": b"MZ"})
    out["wrong identifier"] = _zip(d / "ident.fmu", {"modelDescription.xml": LAG_XML.format(version="2.0",
                                                                                          ident="other"),
                                                     binary: lib})
    out["not a library"] = _zip(d / "garbage.fmu", {"modelDescription.xml": good_xml, binary: b"\x7fELF junk"})
    out["wrong GUID"] = _zip(d / "guid.fmu", {"modelDescription.xml": good_xml.replace("lag-0001", "lag-0002"),
                                              binary: lib})
    if not huge:
        return out
    # 300 MB of description (whitespace compresses to ~300 KB)
    big = d / "huge.fmu"
    with zipfile.ZipFile(big, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        with z.open("modelDescription.xml", "w", force_zip64=True) as f:
            f.write(good_xml.encode()[:-25])
            chunk = b" " * (1 << 20)
            for _ in range(300):
                f.write(chunk)
            f.write(b"</fmiModelDescription>\n")
        z.writestr(binary, lib)
    out["300 MB description"] = big
    return out


# --------------------------------------------------------------------------
# a Co-Simulation FMU around a hand-written model, integrated by RK4
# --------------------------------------------------------------------------
RK4_FMU_C = r"""
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String loc,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    Comp *c = calloc(1, sizeof(Comp));
    if (!c) return NULL;
    c->cb = *cb;
    start(c);
    return c;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean td, fmi2Real tol, fmi2Real t0, fmi2Boolean sd,
                               fmi2Real t1) { ((Comp *)c)->time = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { outputs(c); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { return fmi2Error; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Comp *s = c;
    outputs(s);
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
        s->tin[vr[i]] = s->time;  /* a new value: its derivatives start again from it */
        s->du[0][vr[i]] = s->du[1][vr[i]] = s->du[2][vr[i]] = 0;
    }
    return fmi2OK;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer o[], const fmi2Real v[]) {
#ifdef INTERP
    Comp *s = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= NR || o[i] < 1 || o[i] > 3) return fmi2Error;
        s->du[o[i] - 1][vr[i]] = v[i];
    }
    return fmi2OK;
#else
    return fmi2Error;
#endif
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
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer o[], fmi2Real v[]) { return fmi2Error; }

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSet) {
    Comp *s = c;
    if (!(h > 0)) return fmi2Error;
#ifdef STATUS_AFTER  /* a hostile FMU: refuses every step that ends after STATUS_AFTER with STATUS */
    if (t + h > STATUS_AFTER) return STATUS;
#endif
    int n = (int)ceil(h / 1e-5 - 1e-9);
    double dt = h / n, y[NY], k1[NY], k2[NY], k3[NY], k4[NY], tmp[NY];
    memcpy(y, s->y, sizeof y);
    load(s, y);
    for (int i = 0; i < n; i++) {
        double ti = t + i * dt;
        rhs(s, ti, y, k1);
        for (int j = 0; j < NY; j++) tmp[j] = y[j] + 0.5 * dt * k1[j];
        rhs(s, ti + 0.5 * dt, tmp, k2);
        for (int j = 0; j < NY; j++) tmp[j] = y[j] + 0.5 * dt * k2[j];
        rhs(s, ti + 0.5 * dt, tmp, k3);
        for (int j = 0; j < NY; j++) tmp[j] = y[j] + dt * k3[j];
        rhs(s, ti + dt, tmp, k4);
        for (int j = 0; j < NY; j++) y[j] += dt / 6 * (k1[j] + 2 * k2[j] + 2 * k3[j] + k4[j]);
    }
    for (int j = 0; j < NY; j++) if (!isfinite(y[j])) return fmi2Error;
    memcpy(s->y, y, sizeof y);
    store(s, y);
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

RK4_FMU_HEAD = r"""
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"
"""

RK4_FMU_STATE = r"""
typedef struct {
    double r[NR];  /* the variables, by value reference */
    double du[3][NR], tin[NR];  /* input derivatives the master sent (INTERP), from the time the input was set */
    double y[NY];  /* the states */
    double time;
    fmi2CallbackFunctions cb;
} Comp;

/* an input at time t: the value set, continued by the derivatives the master sent (zero when it sent none) */
static double in(const Comp *c, int vr, double t) {
    double s = t - c->tin[vr];
    return c->r[vr] + s * (c->du[0][vr] + s * (c->du[1][vr] / 2 + s * c->du[2][vr] / 6));
}
"""


def rk4_source(nr: int, ny: int, model_c: str) -> str:
    """The C of an FMU with ``nr`` real variables (by value reference) and ``ny`` states around ``model_c``,
    which defines, on ``Comp *c`` (``c->r[vr]`` the variables, ``c->y`` the states, ``in(c, vr, t)`` an input
    at time t):

    * ``start(c)``: the parameters' values at instantiation;
    * ``rhs(c, t, y, dy)``: the state derivatives;
    * ``load(c, y)``: before a step, states taken from variables (or nothing);
    * ``store(c, y)``: after a step, variables written from the states (or nothing);
    * ``outputs(c)``: the outputs computed before a read and when initialization ends (or nothing).

    Compiled with ``-DINTERP``, the inputs follow the derivatives fmi2SetRealInputDerivatives sends (else it
    refuses them); with ``-DSTATUS_AFTER=t -DSTATUS=fmi2Discard`` (or fmi2Error) fmi2DoStep returns that status
    for every step that ends after t."""
    return RK4_FMU_HEAD + f"#define NR {nr}\n#define NY {ny}\n" + RK4_FMU_STATE + model_c + RK4_FMU_C


def model_description(ident: str, guid: str, variables: list, outputs: list, initial_unknowns=(),
                      fmi_version: str = "2.0", co_simulation: str = "") -> str:
    """modelDescription.xml of a Co-Simulation FMU.  ``variables``: (name, vr, causality, variability, initial,
    start, unit) in the order the indices count; ``outputs``: (index, dependencies or None);
    ``initial_unknowns``: (index, dependencies); ``co_simulation``: more attributes of <CoSimulation>."""
    sv = []
    for name, vr, caus, var, init, start, unit in variables:
        attrs = f'name="{name}" valueReference="{vr}" causality="{caus}" variability="{var}"'
        if init:
            attrs += f' initial="{init}"'
        real = "<Real" + (f' unit="{unit}"' if unit else "") + (f' start="{start!r}"' if start is not None else "") + "/>"
        sv.append(f"    <ScalarVariable {attrs}>{real}</ScalarVariable>")
    units = sorted({v[6] for v in variables if v[6]})
    unit_defs = "".join(f'<Unit name="{u}"/>' for u in units)
    ud = f"\n  <UnitDefinitions>{unit_defs}</UnitDefinitions>" if units else ""
    outs = "".join(f'<Unknown index="{i}"/>' if d is None else f'<Unknown index="{i}" dependencies="{d}"/>'
                   for i, d in outputs)
    iu = "".join(f'<Unknown index="{i}" dependencies="{d}"/>' for i, d in initial_unknowns)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="{fmi_version}" modelName="{ident}" guid="{guid}" generationTool="hand-written C (test)"
    variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{ident}" canHandleVariableCommunicationStepSize="true"{co_simulation}
      canGetAndSetFMUstate="true" canSerializeFMUstate="false" providesDirectionalDerivative="false"/>{ud}
  <ModelVariables>
{chr(10).join(sv)}
  </ModelVariables>
  <ModelStructure><Outputs>{outs}</Outputs>{f"<InitialUnknowns>{iu}</InitialUnknowns>" if iu else ""}</ModelStructure>
</fmiModelDescription>
"""


def compile_fmu(folder: Path, ident: str, source: str, xml: str, cflags=("-O2", "-std=c99"),
                source_name: str = None) -> Path:
    """``folder/ident.fmu``: ``source`` compiled (with ``cflags``) into the shared library ``ident`` and zipped
    with the description ``xml``."""
    folder.mkdir(parents=True, exist_ok=True)
    src = folder / (source_name or f"{ident}.c")
    src.write_text(source)
    lib = folder / f"{ident}{fmpy.sharedLibraryExtension}"
    subprocess.run(["cc", *cflags, "-fPIC", "-shared", f"-I{FMI_HEADERS}", "-o", str(lib), str(src), "-lm"],
                   check=True, capture_output=True, text=True)
    return _zip(folder / f"{ident}.fmu", {"modelDescription.xml": xml,
                                         f"binaries/{fmpy.platform}/{ident}{fmpy.sharedLibraryExtension}":
                                         lib.read_bytes()})


# --------------------------------------------------------------------------
# gains and lags for algebraic loops (tests/test_hardening_loops.py)
# --------------------------------------------------------------------------
# 0 y (output), 1 u (input), 2 a, 3 b, 4 e, 5 T (parameters), 6 k (an Integer parameter, for type mismatches)
GAIN_C = r"""
static void start(Comp *c) { c->r[2] = 1; c->r[3] = 0; c->r[4] = 0; c->r[5] = 0.1; }
static void rhs(const Comp *c, double t, const double *y, double *dy) {
#ifdef LAG
    dy[0] = (in(c, 1, t) - y[0]) / c->r[5];   /* T y' = u - y: the output is a state */
#else
    (void)c; (void)t; (void)y; dy[0] = 0;
#endif
}
static void load(Comp *c, double *y) { (void)c; (void)y; }
static void store(Comp *c, const double *y) { (void)c; (void)y; }
static void outputs(Comp *c) {
#ifdef LAG
    c->r[0] = c->y[0];
#else
    double a = c->r[2];
#ifdef GAIN_RATE
    a += GAIN_RATE * c->time;   /* a gain that changes with time: a loop through it may become singular */
#endif
    c->r[0] = a * in(c, 1, c->time) + c->r[3] + c->r[4] * c->time;   /* y = a u + b + e t, now */
#endif
#ifdef NAN_AFTER
    if (c->time > NAN_AFTER) c->r[0] = NAN;
#endif
}
"""
GAIN_VARIABLES = [("y", 0, "output", "continuous", None, None, "m"), ("u", 1, "input", "continuous", None, 0.0, "m"),
                  ("a", 2, "parameter", "fixed", "exact", 1.0, None), ("b", 3, "parameter", "fixed", "exact", 0.0, "m"),
                  ("e", 4, "parameter", "fixed", "exact", 0.0, None), ("T", 5, "parameter", "fixed", "exact", 0.1, "s")]


def build_gain(folder: Path, ident: str, dependencies="2", lag: bool = False, capabilities: dict = None,
               unit: str = "m", cflags=()) -> Path:
    """``folder/ident.fmu``, a third-party Co-Simulation FMU with input ``u`` and output ``y`` [``unit``]:
    ``y = a u + b + e t`` evaluated when read (a gain: direct feedthrough), or with ``lag`` the state of
    ``T y' = u - y`` (RK4).  ``dependencies``: the output's ModelStructure attribute ("2": on u; "": on
    nothing; None: absent, which FMI 2.0 reads as on every input).  ``capabilities``: <CoSimulation>
    attributes replacing the defaults (canGetAndSetFMUstate, canHandleVariableCommunicationStepSize,
    canInterpolateInputs, maxOutputDerivativeOrder, providesDirectionalDerivative)."""
    variables = [v if v[0] not in ("y", "u") else v[:6] + (unit,) for v in GAIN_VARIABLES]
    xml = model_description(ident, "{gain-%s}" % ident, variables, [(1, dependencies)])
    caps = {"canInterpolateInputs": "true", "maxOutputDerivativeOrder": "0", **(capabilities or {})}
    for key, value in caps.items():
        if f'{key}="' in xml:
            start = xml.index(f'{key}="')
            end = xml.index('"', start + len(key) + 2)
            xml = xml[:start] + f'{key}="{value}"' + xml[end + 1:]
        else:
            xml = xml.replace(f'<CoSimulation modelIdentifier="{ident}"',
                              f'<CoSimulation modelIdentifier="{ident}" {key}="{value}"')
    if unit != "m" and unit:
        xml = xml.replace('<Unit name="m"/>', f'<Unit name="m"/><Unit name="{unit}"/>')
    xml = xml.replace("  </ModelVariables>", '    <ScalarVariable name="k" valueReference="0" causality="parameter" '
                      'variability="fixed" initial="exact"><Integer start="1"/></ScalarVariable>\n  </ModelVariables>')
    flags = ["-O1", "-std=c99", "-DINTERP", *(["-DLAG"] if lag else []), *cflags]
    return compile_fmu(folder, ident, rk4_source(6, 1, GAIN_C), xml, flags, source_name=f"{ident}.c")
