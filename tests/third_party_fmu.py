"""A third-party FMI 2.0 Co-Simulation FMU written from C here, not by fmugen.

``lag``: a first-order lag T y' = u - y stepped exactly over each
communication step with the input held (y <- u + (y - u) exp(-h/T)), one
input ``u``, one output ``y``, a parameter ``T``.  Its modelDescription
declares ``canGetAndSetFMUstate="false"`` and its fmi2GetFMUstate refuses,
as many exported tool FMUs do.  :func:`build_lag` compiles it; :func:`broken_fmus`
writes the broken variants the master must name in one line.
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
    src = d / "lag.c"
    src.write_text(LAG_C)
    lib = d / "lag.so"
    subprocess.run(["cc", "-O1", "-fPIC", "-shared", f"-I{FMI_HEADERS}", "-o", str(lib), str(src), "-lm"],
                   check=True, capture_output=True, text=True)
    return _zip(d / "lag.fmu", {"modelDescription.xml": LAG_XML.format(version="2.0", ident="lag"),
                                f"binaries/{fmpy.platform}/lag{fmpy.sharedLibraryExtension}": lib.read_bytes()})


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
