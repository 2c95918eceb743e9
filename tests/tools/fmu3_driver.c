/* fmu3_driver.c -- a minimal FMI 3.0 Co-Simulation importer for
 * tests/test_platforms_fmi3.py, the FMI 3.0 twin of fmu_driver.c: loads an
 * FMU's shared library by path (LoadLibrary on Windows, dlopen elsewhere),
 * runs one simulation and prints the requested Float64 variables with %.17g
 * at every communication point, so that the x86_64-windows DLL under wine and
 * the x86_64-linux library can be compared digit for digit.
 *
 *   fmu3_driver LIB TOKEN STOP STEP VR,VR,... [VR=VALUE ...]
 *
 * VR=VALUE pairs set Float64 variables (parameters, inputs) before
 * initialisation.  Exits non-zero, with a message, when a call does not return
 * fmi3OK. */
#if defined(__MINGW32__) && !defined(__USE_MINGW_ANSI_STDIO)
#define __USE_MINGW_ANSI_STDIO 1 /* C99 printf: the same %.17g digits as glibc's */
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"

#ifdef _WIN32
#include <windows.h>
static void *open_library(const char *path) { return (void *)LoadLibraryA(path); }
static void *symbol(void *lib, const char *name) { return (void *)GetProcAddress((HMODULE)lib, name); }
#else
#include <dlfcn.h>
static void *open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *symbol(void *lib, const char *name) { return dlsym(lib, name); }
#endif

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    fprintf(stderr, "[status %d, %s] %s\n", (int)status, category ? category : "", message ? message : "");
}

#define MAX_VR 256
#define LOAD(T, f) T f = (T)symbol(lib, #f); if (!f) { fprintf(stderr, "missing %s\n", #f); return 3; }
#define OK(call) do { if ((call) != fmi3OK) { fprintf(stderr, "failed: %s\n", #call); return 4; } } while (0)

int main(int argc, char **argv)
{
    if (argc < 6) {
        fprintf(stderr, "usage: %s LIB TOKEN STOP STEP VR,VR,... [VR=VALUE ...]\n", argv[0]);
        return 2;
    }
    void *lib = open_library(argv[1]);
    if (!lib) {
#ifdef _WIN32
        fprintf(stderr, "cannot load %s (error %lu)\n", argv[1], (unsigned long)GetLastError());
#else
        fprintf(stderr, "cannot load %s: %s\n", argv[1], dlerror());
#endif
        return 3;
    }
    LOAD(fmi3InstantiateCoSimulationTYPE *, fmi3InstantiateCoSimulation)
    LOAD(fmi3EnterInitializationModeTYPE *, fmi3EnterInitializationMode)
    LOAD(fmi3ExitInitializationModeTYPE *, fmi3ExitInitializationMode)
    LOAD(fmi3SetFloat64TYPE *, fmi3SetFloat64)
    LOAD(fmi3GetFloat64TYPE *, fmi3GetFloat64)
    LOAD(fmi3DoStepTYPE *, fmi3DoStep)
    LOAD(fmi3TerminateTYPE *, fmi3Terminate)
    LOAD(fmi3FreeInstanceTYPE *, fmi3FreeInstance)

    double stop = atof(argv[3]), h = atof(argv[4]);
    fmi3ValueReference vr[MAX_VR];
    size_t n = 0;
    for (char *s = strtok(argv[5], ","); s && n < MAX_VR; s = strtok(NULL, ",")) vr[n++] = (fmi3ValueReference)atol(s);

    fmi3Instance c = fmi3InstantiateCoSimulation("driver", argv[2], NULL, fmi3False, fmi3False, fmi3False,
                                                 fmi3False, NULL, 0, NULL, logger, NULL);
    if (!c) { fprintf(stderr, "fmi3InstantiateCoSimulation failed\n"); return 4; }
    for (int a = 6; a < argc; a++) {
        char *eq = strchr(argv[a], '=');
        if (!eq) { fprintf(stderr, "expected VR=VALUE, got %s\n", argv[a]); return 2; }
        fmi3ValueReference r = (fmi3ValueReference)atol(argv[a]);
        fmi3Float64 v = atof(eq + 1);
        OK(fmi3SetFloat64(c, &r, 1, &v, 1));
    }
    OK(fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3True, stop));
    OK(fmi3ExitInitializationMode(c));
    double y[MAX_VR];
    long steps = (long)(stop / h + 0.5);
    for (long k = 0; k <= steps; k++) {
        OK(fmi3GetFloat64(c, vr, n, y, n));
        printf("%.17g", k * h);
        for (size_t i = 0; i < n; i++) printf(" %.17g", y[i]);
        printf("\n");
        if (k < steps) {
            fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
            fmi3Float64 last = 0.0;
            OK(fmi3DoStep(c, k * h, h, fmi3True, &event, &terminate, &early, &last));
            if (terminate) { fprintf(stderr, "the FMU asked to terminate at t = %.17g\n", last); return 5; }
        }
    }
    OK(fmi3Terminate(c));
    fmi3FreeInstance(c);
    return 0;
}
