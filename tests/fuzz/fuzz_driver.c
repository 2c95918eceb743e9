/* fuzz_driver.c -- a seeded random driver of the fmugen FMI 2.0 runtime.
 *
 * Compiled together with the runtime (every c_runtime .c file) and one model.c, under
 * AddressSanitizer and UndefinedBehaviorSanitizer (tests/fuzz/test_fuzz_runtime.py).
 * It plays random sequences of FMI calls -- from fmi2Instantiate to
 * fmi2FreeInstance -- with random arguments: value references in and out of
 * range, NaN, infinities, huge and tiny numbers, step sizes that cannot
 * advance time, flags that are not Booleans, calls in the wrong state, ME
 * calls on CS instances, FMU states of another instance, and serialized FMU
 * states that are truncated, extended, bit-flipped or rewritten field by
 * field and then re-sealed with a valid checksum (so that the semantic checks
 * behind the checksum are reached).
 *
 * Besides the sanitizers (any report aborts the run), it checks invariants of
 * the runtime's contract after every call:
 *   - every return value is fmi2OK, fmi2Warning, fmi2Discard or fmi2Error;
 *   - after fmi2DoStep returned fmi2OK or fmi2Warning, every state and output
 *     is finite (the FMU never says OK about a state it has not checked);
 *   - after ME fmi2GetDerivatives returned fmi2OK, the derivatives are finite.
 *
 *     usage: fuzz_driver SEED SECONDS [MAX_SEQUENCES]   (SECONDS of wall-clock time)
 *     prints: "fuzz: seed S sequences N calls M findings F" and exits F != 0.
 *
 * (No libFuzzer/AFL here: the machine's compiler is gcc, which has no
 * -fsanitize=fuzzer.  The driver is deterministic for a seed, so a finding is
 * reproduced by running the same seed.)
 */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "fmi2Functions.h"
#include "fmugen_model.h"

static uint64_t rng_state;
static uint64_t rnd(void) /* xorshift64* */
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return rng_state * 2685821657736338717ULL;
}
static int rndi(int n) { return n > 0 ? (int)(rnd() % (uint64_t)n) : 0; }

static long long n_calls = 0, n_steps_ok = 0, n_restored = 0, n_restored_mutated = 0;
static int findings = 0;
static unsigned long long seed0;
static long long seq_no;

#define FINDING(...)                                                                       \
    do {                                                                                   \
        findings++;                                                                        \
        printf("fuzz: FINDING seed %llu sequence %lld: ", seed0, seq_no);                  \
        printf(__VA_ARGS__);                                                               \
        printf("\n");                                                                      \
    } while (0)

/* the logger formats the message as FMI 2.0 says it is: a printf format */
static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env; (void)status;
    char buf[4096];
    va_list ap;
    va_start(ap, message);
    vsnprintf(buf, sizeof buf, message ? message : "(null)", ap);
    va_end(ap);
    if (!name || !category) FINDING("logger called with a NULL instance name or category");
    if (getenv("FUZZ_VERBOSE")) printf("  log %d %s: %s\n", (int)status, category, buf);
}

static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

static double rnd_double(void)
{
    static const double special[] = {0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 1e300, -1e300, 5e-324, 1e15, 1e10,
                                     0.01, 1e-9, 2.0, 0.5, 1e6};
    switch (rndi(10)) {
    case 0: return NAN;
    case 1: return rndi(2) ? INFINITY : -INFINITY;
    case 2: case 3: return special[rndi((int)(sizeof special / sizeof special[0]))];
    default: return ((double)rndi(2000001) - 1000000.0) * pow(10.0, rndi(13) - 9) * 1e-3;
    }
}

static fmi2Status checked(fmi2Status s, const char *fn)
{
    n_calls++;
    if (s != fmi2OK && s != fmi2Warning && s != fmi2Discard && s != fmi2Error)
        FINDING("%s returned status %d", fn, (int)s);
    return s;
}

static int n_real(void) { return 2 * fmugen_model.nx + fmugen_model.nu + fmugen_model.ny + fmugen_model.np + FMUGEN_RT_COUNT; }

static fmi2ValueReference rnd_vr(int n)
{
    switch (rndi(8)) {
    case 0: return (fmi2ValueReference)(n + rndi(5));
    case 1: return (fmi2ValueReference)(rnd() & 0xffffffffu);
    default: return (fmi2ValueReference)rndi(n > 0 ? n : 1);
    }
}

/* all states and outputs finite? (the CS contract after fmi2OK/fmi2Warning) */
static void check_finite_after_step(fmi2Component c, const char *what)
{
    const int nx = fmugen_model.nx, ny = fmugen_model.ny, nu = fmugen_model.nu;
    fmi2ValueReference vr[64];
    double v[64];
    int n = 0;
    for (int i = 0; i < nx && n < 64; i++) vr[n++] = (fmi2ValueReference)i;
    for (int i = 0; i < ny && n < 64; i++) vr[n++] = (fmi2ValueReference)(2 * nx + nu + i);
    if (n == 0) return;
    fmi2Status s = checked(fmi2GetReal(c, vr, (size_t)n, v), "fmi2GetReal");
    if (s != fmi2OK) { FINDING("fmi2GetReal of states/outputs failed (%d) after %s", (int)s, what); return; }
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i])) FINDING("value reference %u = %g after %s returned OK/Warning", vr[i], v[i], what);
}

/* FNV-1a, as c_runtime/fmu_state.c seals a blob */
static uint64_t fnv1a(const unsigned char *p, size_t n)
{
    uint64_t h = 1469598103934665603ULL;
    for (size_t i = 0; i < n; i++) { h ^= p[i]; h *= 1099511628211ULL; }
    return h;
}

static void mutate_blob(fmi2Byte **blob, size_t *n)
{
    unsigned char *b = (unsigned char *)*blob;
    switch (rndi(7)) {
    case 0: if (*n) b[rndi((int)*n)] ^= (unsigned char)(1u << rndi(8)); break;          /* bit flip */
    case 1: if (*n) *n = (size_t)rndi((int)*n); break;                                   /* truncate */
    case 2: {                                                                            /* extend */
        size_t extra = 1 + (size_t)rndi(64);
        unsigned char *nb = realloc(b, *n + extra);
        if (!nb) return;
        for (size_t i = 0; i < extra; i++) nb[*n + i] = (unsigned char)rnd();
        *blob = (fmi2Byte *)nb;
        *n += extra;
        return;
    }
    case 3: case 4: case 5: { /* overwrite one 8-byte field behind the header with a wild value, re-seal */
        if (*n < 24) return;
        size_t fields = (*n - 8) / 8, k = (size_t)rndi((int)fields);
        size_t off = k * 8;
        if (off + 8 > *n - 8) return;
        double d = rnd_double();
        int64_t i64 = (int64_t)(rnd() % 7) - 1 + (rndi(4) == 0 ? (int64_t)rnd() : 0);
        if (rndi(2)) memcpy(b + off, &d, 8); else memcpy(b + off, &i64, 8);
        uint64_t h = fnv1a(b, *n - 8);
        memcpy(b + *n - 8, &h, 8);
        break;
    }
    default: for (size_t i = 0; i < *n; i++) b[i] = (unsigned char)rnd(); break;          /* noise */
    }
}

#define MAX_STATES 4

static void run_sequence(int max_calls)
{
    const int me = rndi(2);
    const char *names[] = {"fuzz", "%s%n%s%n", "", "inst\n\"<>&", NULL};
    const char *guid = rndi(20) ? fmugen_model.guid : (rndi(2) ? "{wrong-guid}" : NULL);
    fmi2Type type = rndi(50) ? (me ? fmi2ModelExchange : fmi2CoSimulation) : (fmi2Type)(2 + rndi(5));
    fmi2Component c = fmi2Instantiate(names[rndi(30) ? rndi(4) : 4], type, guid, rndi(10) ? "" : NULL,
                                      rndi(30) ? &callbacks : NULL, fmi2False, (fmi2Boolean)rndi(2));
    n_calls++;
    if (!c) return;
    fmi2Component other = rndi(4) == 0 ? fmi2Instantiate("other", me ? fmi2CoSimulation : fmi2ModelExchange,
                                                         fmugen_model.guid, "", &callbacks, fmi2False, fmi2False)
                                       : NULL;
    fmi2FMUstate states[MAX_STATES] = {0};
    fmi2FMUstate other_state = NULL;
    if (other) checked(fmi2GetFMUstate(other, &other_state), "fmi2GetFMUstate(other)");
    double t = 0.0;
    const int nr = n_real();
    for (int k = 0; k < max_calls; k++) {
        fmi2ValueReference vr[8];
        double v[8];
        fmi2Integer iv[8], order[8];
        fmi2Boolean bv[8];
        fmi2String sv[8];
        size_t n = (size_t)rndi(9);
        for (size_t i = 0; i < n; i++) {
            vr[i] = rnd_vr(nr);
            v[i] = rnd_double();
            iv[i] = rndi(3) ? rndi(5) - 1 : (fmi2Integer)rnd();
            order[i] = rndi(4) - 1;
            bv[i] = rndi(3);
            sv[i] = "s";
        }
        int op = rndi(34);
        if (k == 0 && rndi(4)) { /* mostly a well-formed start, so that sequences reach deep states */
            checked(fmi2SetupExperiment(c, fmi2True, 1e-6, t = rndi(4) ? 0.0 : 1e3 * rnd_double(), fmi2False, 0),
                    "fmi2SetupExperiment");
            checked(fmi2EnterInitializationMode(c), "fmi2EnterInitializationMode");
            if (rndi(2)) checked(fmi2SetReal(c, vr, n, v), "fmi2SetReal");
            checked(fmi2ExitInitializationMode(c), "fmi2ExitInitializationMode");
            if (me) {
                fmi2EventInfo ei;
                checked(fmi2NewDiscreteStates(c, &ei), "fmi2NewDiscreteStates");
                checked(fmi2EnterContinuousTimeMode(c), "fmi2EnterContinuousTimeMode");
            }
            continue;
        }
        switch (op) {
        case 0: checked(fmi2SetupExperiment(c, (fmi2Boolean)rndi(3), rnd_double(), t = rndi(3) ? 0.0 : rnd_double(),
                                            (fmi2Boolean)rndi(2), rnd_double()), "fmi2SetupExperiment"); break;
        case 1: checked(fmi2EnterInitializationMode(c), "fmi2EnterInitializationMode"); break;
        case 2: checked(fmi2ExitInitializationMode(c), "fmi2ExitInitializationMode"); break;
        case 3: checked(fmi2SetReal(c, vr, n, v), "fmi2SetReal"); break;
        case 4: checked(fmi2GetReal(c, vr, n, v), "fmi2GetReal"); break;
        case 5: checked(fmi2SetInteger(c, (const fmi2ValueReference *)vr, n, iv), "fmi2SetInteger"); break;
        case 6: checked(fmi2GetInteger(c, vr, n, iv), "fmi2GetInteger"); break;
        case 7: checked(fmi2SetBoolean(c, vr, n, bv), "fmi2SetBoolean"); checked(fmi2GetBoolean(c, vr, n, bv), "fmi2GetBoolean"); break;
        case 8: checked(fmi2SetString(c, vr, n, sv), "fmi2SetString"); checked(fmi2GetString(c, vr, n, sv), "fmi2GetString"); break;
        case 9: case 10: case 11: case 12: { /* fmi2DoStep: mostly sensible, sometimes wild */
            double tc = t, h = rndi(4) ? 0.01 * (1 + rndi(50)) : rnd_double();
            fmi2Real lst = 0;
            if (rndi(5) == 0) tc = rnd_double();
            fmi2Boolean flag = rndi(6) ? (fmi2Boolean)rndi(2) : (fmi2Boolean)rndi(100);
            fmi2Status s = checked(fmi2DoStep(c, tc, h, flag), "fmi2DoStep");
            if (s == fmi2OK || s == fmi2Warning) { t = tc + h; n_steps_ok++; check_finite_after_step(c, "fmi2DoStep"); }
            else if (fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &lst) == fmi2OK) t = lst;
            break;
        }
        case 13: checked(fmi2SetRealInputDerivatives(c, vr, n, order, v), "fmi2SetRealInputDerivatives"); break;
        case 14: checked(fmi2GetRealOutputDerivatives(c, vr, n, order, v), "fmi2GetRealOutputDerivatives"); break;
        case 15: {
            fmi2ValueReference kn[8];
            size_t nk = (size_t)rndi(9);
            for (size_t i = 0; i < nk; i++) kn[i] = rnd_vr(nr);
            double dv[8] = {1, 0, 1, 0, 1, 0, 1, 0}, out[8];
            checked(fmi2GetDirectionalDerivative(c, vr, n, kn, nk, dv, out), "fmi2GetDirectionalDerivative");
            break;
        }
        case 16: checked(fmi2EnterEventMode(c), "fmi2EnterEventMode"); break;
        case 17: { fmi2EventInfo ei; checked(fmi2NewDiscreteStates(c, rndi(10) ? &ei : NULL), "fmi2NewDiscreteStates"); break; }
        case 18: checked(fmi2EnterContinuousTimeMode(c), "fmi2EnterContinuousTimeMode"); break;
        case 19: {
            double tt = rndi(3) ? t + 0.01 * rndi(10) - 0.02 : rnd_double();
            if (checked(fmi2SetTime(c, tt), "fmi2SetTime") == fmi2OK) t = tt;
            break;
        }
        case 20: {
            double x[64], dx[64];
            size_t nx = rndi(5) ? (size_t)fmugen_model.nx : (size_t)rndi(6);
            for (size_t i = 0; i < nx && i < 64; i++) x[i] = rndi(4) ? (double)rndi(5) - 2.0 : rnd_double();
            checked(fmi2SetContinuousStates(c, x, nx), "fmi2SetContinuousStates");
            if (checked(fmi2GetDerivatives(c, dx, nx), "fmi2GetDerivatives") == fmi2OK)
                for (size_t i = 0; i < nx; i++)
                    if (!isfinite(dx[i])) FINDING("fmi2GetDerivatives returned OK with der[%zu] = %g", i, dx[i]);
            checked(fmi2GetContinuousStates(c, x, nx), "fmi2GetContinuousStates");
            checked(fmi2GetNominalsOfContinuousStates(c, x, nx), "fmi2GetNominalsOfContinuousStates");
            checked(fmi2GetEventIndicators(c, x, (size_t)rndi(2)), "fmi2GetEventIndicators");
            break;
        }
        case 21: {
            fmi2Boolean enter = 0, term = 0;
            checked(fmi2CompletedIntegratorStep(c, rndi(5) ? (fmi2Boolean)rndi(2) : (fmi2Boolean)rndi(50),
                                                rndi(10) ? &enter : NULL, &term), "fmi2CompletedIntegratorStep");
            break;
        }
        case 22: case 23: { /* get a state into a slot (new or reused) */
            int slot = rndi(MAX_STATES);
            checked(fmi2GetFMUstate(c, &states[slot]), "fmi2GetFMUstate");
            break;
        }
        case 24: {
            int slot = rndi(MAX_STATES);
            fmi2FMUstate st = rndi(6) == 0 ? other_state : states[slot];
            checked(fmi2SetFMUstate(c, st), "fmi2SetFMUstate");
            fmi2Real lst = 0;
            if (fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &lst) == fmi2OK) t = lst;
            break;
        }
        case 25: {
            int slot = rndi(MAX_STATES);
            checked(fmi2FreeFMUstate(c, &states[slot]), "fmi2FreeFMUstate");
            states[slot] = NULL;
            break;
        }
        case 26: case 27: case 28: { /* serialize, mutate, deserialize, use */
            int slot = rndi(MAX_STATES);
            if (!states[slot]) { checked(fmi2GetFMUstate(c, &states[slot]), "fmi2GetFMUstate"); break; }
            size_t size = 0;
            if (checked(fmi2SerializedFMUstateSize(c, states[slot], &size), "fmi2SerializedFMUstateSize") != fmi2OK) break;
            fmi2Byte *blob = malloc(size + 1);
            if (!blob) break;
            size_t given = rndi(8) ? size : (size_t)rndi((int)size + 2);
            if (checked(fmi2SerializeFMUstate(c, states[slot], blob, given), "fmi2SerializeFMUstate") == fmi2OK) {
                int mutated = rndi(4) != 0;
                if (mutated) mutate_blob(&blob, &size);
                fmi2FMUstate st = NULL;
                int target = rndi(MAX_STATES);
                fmi2FMUstate *dest = rndi(3) ? &st : &states[target];
                if (checked(fmi2DeSerializeFMUstate(c, blob, size, dest), "fmi2DeSerializeFMUstate") == fmi2OK &&
                    checked(fmi2SetFMUstate(c, *dest), "fmi2SetFMUstate") == fmi2OK) {
                    n_restored++;
                    n_restored_mutated += mutated;
                    fmi2Real lst = 0;
                    if (fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &lst) == fmi2OK) t = lst;
                    for (int j = 0; j < 3; j++) {
                        fmi2Status s = checked(fmi2DoStep(c, t, 0.01, fmi2True), "fmi2DoStep");
                        if (s == fmi2OK || s == fmi2Warning) { t += 0.01; check_finite_after_step(c, "fmi2DoStep after deserialize"); }
                        else break;
                    }
                    double dx[64];
                    if (checked(fmi2GetDerivatives(c, dx, (size_t)fmugen_model.nx), "fmi2GetDerivatives") == fmi2OK)
                        for (int i = 0; i < fmugen_model.nx; i++)
                            if (!isfinite(dx[i])) FINDING("fmi2GetDerivatives OK with der[%d] = %g after a restored blob", i, dx[i]);
                }
                if (dest == &st && st) checked(fmi2FreeFMUstate(c, &st), "fmi2FreeFMUstate");
            }
            free(blob);
            break;
        }
        case 29: { fmi2Status s; fmi2Real r; fmi2Integer i; fmi2Boolean b; fmi2String str;
            checked(fmi2GetStatus(c, (fmi2StatusKind)rndi(5), &s), "fmi2GetStatus");
            checked(fmi2GetRealStatus(c, (fmi2StatusKind)rndi(5), &r), "fmi2GetRealStatus");
            checked(fmi2GetIntegerStatus(c, (fmi2StatusKind)rndi(5), &i), "fmi2GetIntegerStatus");
            checked(fmi2GetBooleanStatus(c, (fmi2StatusKind)rndi(5), &b), "fmi2GetBooleanStatus");
            checked(fmi2GetStringStatus(c, (fmi2StatusKind)rndi(5), &str), "fmi2GetStringStatus");
            checked(fmi2CancelStep(c), "fmi2CancelStep");
            break; }
        case 30: {
            fmi2String cats[] = {"logEvents", "logAll", "nonsense", "logStatusError"};
            checked(fmi2SetDebugLogging(c, (fmi2Boolean)rndi(2), (size_t)rndi(5), cats), "fmi2SetDebugLogging");
            break;
        }
        case 31: checked(fmi2Terminate(c), "fmi2Terminate"); break;
        case 32: if (rndi(4) == 0) { checked(fmi2Reset(c), "fmi2Reset"); t = 0.0; } break;
        default: { /* a sensible burst of steps from the current time */
            for (int j = 0; j < 5; j++) {
                fmi2Status s = checked(fmi2DoStep(c, t, 0.05, fmi2True), "fmi2DoStep");
                if (s == fmi2OK || s == fmi2Warning) { t += 0.05; check_finite_after_step(c, "fmi2DoStep"); }
                else break;
            }
        }
        }
    }
    for (int i = 0; i < MAX_STATES; i++)
        if (states[i]) checked(fmi2FreeFMUstate(c, &states[i]), "fmi2FreeFMUstate");
    if (other) {
        if (other_state) fmi2FreeFMUstate(other, &other_state);
        fmi2FreeInstance(other);
    }
    fmi2FreeInstance(c);
    n_calls++;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: %s SEED SECONDS [MAX_SEQUENCES]\n", argv[0]);
        return 2;
    }
    seed0 = strtoull(argv[1], NULL, 10);
    const double seconds = atof(argv[2]);
    const long long max_seq = argc > 3 ? atoll(argv[3]) : -1;
    struct timespec ts0, ts;
    clock_gettime(CLOCK_MONOTONIC, &ts0);
    for (seq_no = 0; max_seq < 0 || seq_no < max_seq; seq_no++) {
        rng_state = seed0 * 0x9E3779B97F4A7C15ULL + (uint64_t)seq_no * 0xD1B54A32D192ED03ULL + 1;
        run_sequence(1 + rndi(120));
        clock_gettime(CLOCK_MONOTONIC, &ts);
        if ((double)(ts.tv_sec - ts0.tv_sec) + 1e-9 * (double)(ts.tv_nsec - ts0.tv_nsec) > seconds) { seq_no++; break; }
    }
    printf("fuzz: seed %llu sequences %lld calls %lld (steps completed %lld, FMU states restored from blobs %lld, "
           "of them mutated and re-sealed %lld) findings %d\n", seed0, seq_no, n_calls, n_steps_ok, n_restored,
           n_restored_mutated, findings);
    return findings != 0;
}
