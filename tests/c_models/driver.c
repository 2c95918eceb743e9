/* driver.c -- a plain C importer of the runtime linked with the vdp test
 * model, run under valgrind by tests/test_runtime_c.py: ME and CS with every
 * solver, misuse, model failure, FMU state and serialisation.  Prints
 * "driver: all checks passed" and exits 0 when every check holds. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"
#include "fmugen_model.h"

static int failures = 0, n_log = 0;
#define CHECK(cond)                                                         \
    do {                                                                    \
        if (!(cond)) { printf("driver: check failed line %d: %s\n", __LINE__, #cond); failures++; } \
    } while (0)

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env; (void)name; (void)status; (void)category; (void)message;
    n_log++;
}

static const fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};

static void run_cs(int solver, double *x_end)
{
    fmi2Component c = fmi2Instantiate("cs", fmi2CoSimulation, fmugen_model.guid, "", &cb, fmi2False, fmi2True);
    CHECK(c != NULL);
    fmi2ValueReference vr_solver = 0, vr_fixed = 13, vr_F = 4, vr_x[2] = {0, 1};
    fmi2Integer s = solver;
    double h = 0.01, F = 0.3;
    CHECK(fmi2SetupExperiment(c, fmi2False, 0, 0.0, fmi2True, 2.0) == fmi2OK);
    CHECK(fmi2SetInteger(c, &vr_solver, 1, &s) == fmi2OK);
    CHECK(fmi2SetReal(c, &vr_fixed, 1, &h) == fmi2OK);
    CHECK(fmi2EnterInitializationMode(c) == fmi2OK);
    CHECK(fmi2SetReal(c, &vr_F, 1, &F) == fmi2OK);
    CHECK(fmi2ExitInitializationMode(c) == fmi2OK);
    fmi2FMUstate st = NULL;
    for (int k = 0; k < 20; k++) {
        if (k == 10) CHECK(fmi2GetFMUstate(c, &st) == fmi2OK);
        CHECK(fmi2DoStep(c, 0.1 * k, 0.1, fmi2True) == fmi2OK);
    }
    CHECK(fmi2GetReal(c, vr_x, 2, x_end) == fmi2OK);
    /* serialise, restore, redo the second half: identical */
    size_t n = 0;
    CHECK(fmi2SerializedFMUstateSize(c, st, &n) == fmi2OK);
    fmi2Byte *blob = malloc(n);
    CHECK(fmi2SerializeFMUstate(c, st, blob, n) == fmi2OK);
    fmi2FMUstate st2 = NULL;
    CHECK(fmi2DeSerializeFMUstate(c, blob, n, &st2) == fmi2OK);
    blob[n / 2] ^= 1;
    fmi2FMUstate st3 = NULL;
    CHECK(fmi2DeSerializeFMUstate(c, blob, n, &st3) == fmi2Error && st3 == NULL);
    CHECK(fmi2DeSerializeFMUstate(c, blob, n - 3, &st3) == fmi2Error);
    free(blob);
    CHECK(fmi2SetFMUstate(c, st2) == fmi2OK);
    for (int k = 10; k < 20; k++) CHECK(fmi2DoStep(c, 0.1 * k, 0.1, fmi2True) == fmi2OK);
    double x2[2];
    CHECK(fmi2GetReal(c, vr_x, 2, x2) == fmi2OK);
    CHECK(x2[0] == x_end[0] && x2[1] == x_end[1]);
    CHECK(fmi2DoStep(c, 2.0, 0.1, fmi2True) == fmi2Error); /* past the stop time */
    CHECK(fmi2FreeFMUstate(c, &st) == fmi2OK && st == NULL);
    CHECK(fmi2FreeFMUstate(c, &st2) == fmi2OK);
    CHECK(fmi2Terminate(c) == fmi2OK);
    fmi2FreeInstance(c);
}

int main(void)
{
    double xe[3][2];
    for (int s = 1; s <= 3; s++) run_cs(s, xe[s - 1]);
    CHECK(fabs(xe[0][0] - xe[1][0]) < 1e-4 && fabs(xe[0][0] - xe[2][0]) < 1e-4);

    /* Model Exchange with explicit Euler, plus misuse */
    fmi2Component c = fmi2Instantiate("me", fmi2ModelExchange, fmugen_model.guid, "", &cb, fmi2False, fmi2False);
    CHECK(c != NULL);
    int before = n_log;
    CHECK(fmi2DoStep(c, 0, 0.1, fmi2True) == fmi2Error);
    CHECK(fmi2SetReal(c, NULL, 3, NULL) == fmi2Error);
    double nan = NAN;
    fmi2ValueReference vr_F = 4, vr_m = 8, vr_bad = 4711, vr_der = 2;
    CHECK(fmi2SetReal(c, &vr_F, 1, &nan) == fmi2Error);
    CHECK(fmi2SetReal(c, &vr_bad, 1, &nan) == fmi2Error);
    CHECK(fmi2SetReal(c, &vr_der, 1, &nan) == fmi2Error);
    CHECK(n_log >= before + 5);
    CHECK(fmi2EnterInitializationMode(c) == fmi2OK);
    CHECK(fmi2ExitInitializationMode(c) == fmi2OK);
    fmi2EventInfo ei;
    CHECK(fmi2NewDiscreteStates(c, &ei) == fmi2OK && !ei.newDiscreteStatesNeeded);
    CHECK(fmi2EnterContinuousTimeMode(c) == fmi2OK);
    double x[2], dx[2], t = 0;
    CHECK(fmi2GetContinuousStates(c, x, 2) == fmi2OK);
    for (int k = 0; k < 1000; k++) {
        CHECK(fmi2GetDerivatives(c, dx, 2) == fmi2OK);
        t += 1e-3;
        x[0] += 1e-3 * dx[0];
        x[1] += 1e-3 * dx[1];
        CHECK(fmi2SetTime(c, t) == fmi2OK);
        CHECK(fmi2SetContinuousStates(c, x, 2) == fmi2OK);
        fmi2Boolean em, ts;
        CHECK(fmi2CompletedIntegratorStep(c, fmi2True, &em, &ts) == fmi2OK);
    }
    fmi2ValueReference unk[2] = {2, 3}, kn[3] = {0, 1, 4};
    double dv[3] = {1, 0.5, -1}, du[2];
    CHECK(fmi2GetDirectionalDerivative(c, unk, 2, kn, 3, dv, du) == fmi2OK);
    CHECK(fmi2GetDerivatives(c, NULL, 2) == fmi2Error);
    CHECK(fmi2Terminate(c) == fmi2OK);
    CHECK(fmi2Reset(c) == fmi2OK);
    double m = -1;
    CHECK(fmi2SetReal(c, &vr_m, 1, &m) == fmi2OK);
    CHECK(fmi2EnterInitializationMode(c) == fmi2OK);
    CHECK(fmi2ExitInitializationMode(c) == fmi2Error); /* mass not positive definite */
    fmi2FreeInstance(c);
    fmi2FreeInstance(NULL);
    CHECK(fmi2Instantiate("x", fmi2ModelExchange, "{bad}", "", &cb, fmi2False, fmi2False) == NULL);
    CHECK(fmi2Instantiate("x", fmi2ModelExchange, fmugen_model.guid, "", NULL, fmi2False, fmi2False) == NULL);
    if (failures) return 1;
    printf("driver: all checks passed\n");
    return 0;
}
