/* fmu_driver.c -- a minimal FMI 2.0 Co-Simulation importer for
 * tests/test_platforms.py: loads an FMU's shared library by path
 * (LoadLibrary on Windows, dlopen elsewhere), runs one simulation and prints
 * the requested Reals with %.17g at every communication point, so that the
 * same run of a win64 DLL under wine and of the linux64 .so can be compared
 * digit for digit.
 *
 *   fmu_driver LIB GUID STOP STEP VR,VR,... [VR=VALUE ...]
 *
 * VR=VALUE pairs set Reals (parameters, inputs) before initialisation.
 * Exits non-zero, with a message, when a call does not return fmi2OK. */
#if defined(__MINGW32__) && !defined(__USE_MINGW_ANSI_STDIO)
#define __USE_MINGW_ANSI_STDIO 1 /* C99 printf: the same %.17g digits as glibc's */
#endif
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

#ifdef _WIN32
#include <windows.h>
static void *open_library(const char *path) { return (void *)LoadLibraryA(path); }
static void *symbol(void *lib, const char *name) { return (void *)GetProcAddress((HMODULE)lib, name); }
#else
#include <dlfcn.h>
static void *open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *symbol(void *lib, const char *name) { return dlsym(lib, name); }
#endif

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env; (void)category;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%s status %d] ", name, (int)status);
    vfprintf(stderr, message, ap);
    fprintf(stderr, "\n");
    va_end(ap);
}

#define MAX_VR 256
#define LOAD(T, f) T f = (T)symbol(lib, #f); if (!f) { fprintf(stderr, "missing %s\n", #f); return 3; }
#define OK(call) do { if ((call) != fmi2OK) { fprintf(stderr, "failed: %s\n", #call); return 4; } } while (0)

int main(int argc, char **argv)
{
    if (argc < 6) {
        fprintf(stderr, "usage: %s LIB GUID STOP STEP VR,VR,... [VR=VALUE ...]\n", argv[0]);
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
    LOAD(fmi2InstantiateTYPE *, fmi2Instantiate)
    LOAD(fmi2SetupExperimentTYPE *, fmi2SetupExperiment)
    LOAD(fmi2EnterInitializationModeTYPE *, fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationModeTYPE *, fmi2ExitInitializationMode)
    LOAD(fmi2SetRealTYPE *, fmi2SetReal)
    LOAD(fmi2GetRealTYPE *, fmi2GetReal)
    LOAD(fmi2DoStepTYPE *, fmi2DoStep)
    LOAD(fmi2TerminateTYPE *, fmi2Terminate)
    LOAD(fmi2FreeInstanceTYPE *, fmi2FreeInstance)

    double stop = atof(argv[3]), h = atof(argv[4]);
    fmi2ValueReference vr[MAX_VR];
    size_t n = 0;
    for (char *s = strtok(argv[5], ","); s && n < MAX_VR; s = strtok(NULL, ",")) vr[n++] = (fmi2ValueReference)atol(s);

    static const fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("driver", fmi2CoSimulation, argv[2], "", &cb, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 4; }
    OK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop));
    for (int a = 6; a < argc; a++) {
        char *eq = strchr(argv[a], '=');
        if (!eq) { fprintf(stderr, "expected VR=VALUE, got %s\n", argv[a]); return 2; }
        fmi2ValueReference r = (fmi2ValueReference)atol(argv[a]);
        fmi2Real v = atof(eq + 1);
        OK(fmi2SetReal(c, &r, 1, &v));
    }
    OK(fmi2EnterInitializationMode(c));
    OK(fmi2ExitInitializationMode(c));
    double y[MAX_VR];
    long steps = (long)(stop / h + 0.5);
    for (long k = 0; k <= steps; k++) {
        OK(fmi2GetReal(c, vr, n, y));
        printf("%.17g", k * h);
        for (size_t i = 0; i < n; i++) printf(" %.17g", y[i]);
        printf("\n");
        if (k < steps) OK(fmi2DoStep(c, k * h, h, fmi2True));
    }
    OK(fmi2Terminate(c));
    fmi2FreeInstance(c);
    return 0;
}
