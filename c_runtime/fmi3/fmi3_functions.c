/*
 * fmi3_functions.c -- the FMI 3.0 interface of fmugen's runtime (opt-in:
 * fmugen build --fmi-version 3).
 *
 * Not a second runtime: every FMI 3.0 function is a thin translation onto
 * the FMI 2.0 functions of c_runtime/ (fmi2_functions.c, fmi2_model_exchange.c,
 * fmi2_co_simulation.c, fmu_state.c), which are linked into the same binary
 * as internals (fmi3_exports.map keeps them out of its exported symbols).  So
 * the state machine, the argument checks, the solvers, the event iteration and
 * the FMU state are the same code for both versions, and an FMI 3.0 FMU
 * computes bit for bit what the FMI 2.0 FMU of the same model computes.
 *
 * What the translation adds:
 *   - the logger: FMI 3.0's fmi3LogMessageCallback (no instance name, not
 *     variadic) behind an FMI 2.0 logger, with the fmi2 function names of the
 *     runtime's messages given as the fmi3 function the importer called;
 *   - value references: FMI 3.0 has one value-reference space for all types,
 *     so the Float64 variables keep the FMI 2.0 Real ones, the event
 *     indicators (FMI 3.0 <EventIndicator> elements name variables) follow
 *     at fmugen_vr_end(m) .. +nz, the Int32 variables (FMUGEN_INT_*)
 *     after them (fmi3_int_base), and last the independent variable time
 *     (FMI 3.0 requires one; fmi3_time_vr); modelDescription.xml
 *     (fmugen/fmi/model_description3.py) writes the same layout;
 *   - fmi3EnterInitializationMode takes fmi2SetupExperiment's arguments;
 *   - fmi3UpdateDiscreteStates / fmi3DoStep return fmi2EventInfo's flags and
 *     fmi2GetRealStatus's lastSuccessfulTime as output arguments;
 *   - Co-Simulation Event Mode and early return (FMI 3.0 sec. 4.1 "Early
 *     Return", 4.2 Step Mode and fmi3EnterEventMode): eventModeUsed and
 *     earlyReturnAllowed of fmi3InstantiateCoSimulation go to fmi2DoStep
 *     through fmugen_cs_ext (inst->cs_ext; NULL when neither is asked for and
 *     there is no callback, and for FMI 2.0, so those steps stay exactly FMI
 *     2.0's).  With eventModeUsed an event ends the step unhandled:
 *     eventHandlingNeeded, earlyReturn (when allowed; not for an event at the
 *     step's end), lastSuccessfulTime = its time; fmi3EnterEventMode,
 *     fmi3UpdateDiscreteStates (the whole event iteration of the step, with the
 *     inputs set in Event Mode: discreteStatesNeedUpdate false after one call)
 *     and fmi3EnterStepMode go on.  fmi3ExitInitializationMode enters Event
 *     Mode then (the initial iteration has run; nothing is pending).
 *     hasEventMode is true for models with events only (modelDescription.xml);
 *     eventModeUsed is refused for the others, as the standard requires;
 *   - the intermediate update: after every accepted internal solver step the
 *     importer's callback, with intermediateVariableSetRequested false,
 *     intermediateVariableGetAllowed and intermediateStepFinished true,
 *     canReturnEarly = earlyReturnAllowed before the step's end;
 *     earlyReturnRequested ends the step at earlyReturnTime (at the callback's
 *     time when that has passed).  Inside it only getting is allowed:
 *     everything that changes the instance returns fmi3Error with a message (a
 *     nested fmi3DoStep, setting, Event Mode, FMU state, fmi3FreeInstance,
 *     fmi3Terminate ...);
 *   - inputs set in the intermediate update (FMI 3.0's replacement for FMI
 *     2.0's input derivatives): when requiredIntermediateVariables names inputs
 *     (intermediateUpdate="true" in modelDescription.xml), the callback comes
 *     with intermediateVariableSetRequested true wherever the solver needs u(t)
 *     inside the step (intermediate_inputs: each distinct stage time, event
 *     location, sample instant, the step's end), and fmi3SetFloat64 of those
 *     inputs -- only that -- gives the solver u(t) there (fmugen_cs_ext.inputs_at).
 *     An importer that sets the values of a polynomial gets what an FMI 2.0
 *     FMU computes with that polynomial's input derivatives.
 *
 * Not supported yet (present, because the standard requires every symbol,
 * and returning fmi3Error with a logged message): Scheduled Execution,
 * clocks, configuration mode,
 * adjoint derivatives, variable dependencies at run time, and variables of
 * types other than Float64 and Int32 (there are none).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmugen_runtime.h"
#include "solver.h"
#include "fmi3Functions.h"

#define INST ((fmugen_instance *)instance)
#define MASK_GET                                                                                      \
    (FMUGEN_INITIALIZATION_MODE | FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | FMUGEN_STEP_COMPLETE | \
     FMUGEN_STEP_FAILED | FMUGEN_TERMINATED | FMUGEN_ERROR)
#define ANY_STATE                                                                                     \
    (FMUGEN_INSTANTIATED | FMUGEN_INITIALIZATION_MODE | FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | \
     FMUGEN_STEP_COMPLETE | FMUGEN_STEP_FAILED | FMUGEN_TERMINATED | FMUGEN_ERROR)

/* ------------------------------------------------------------------------ */
/* the logger                                                                */
/* ------------------------------------------------------------------------ */

/* The FMI 2.0 logger's environment, and with it what FMI 3.0 Co-Simulation adds to an instance: the
 * runtime reaches it as inst->cb.componentEnvironment, fmi2DoStep as inst->cs_ext (&ext). */
typedef struct fmi3_bridge {
    fmi3LogMessageCallback log;
    fmi3InstanceEnvironment env;
    fmugen_cs_ext ext;                              /* eventModeUsed, earlyReturnAllowed, the step hook */
    fmi3IntermediateUpdateCallback intermediate_update; /* NULL: none given */
    int in_intermediate_update;                     /* inside that callback: IU_GET or IU_SET, else 0 */
    /* inputs set in the intermediate update (requiredIntermediateVariables named some): */
    unsigned char *iu_required;                     /* nu: input i was named, so the importer may set it */
    double *iu_u;                                   /* nu: the inputs as last set (the last value set remains) */
    double iu_time;                                 /* time of the last set request in the running step */
    int iu_valid;                                   /* iu_u is the importer's for iu_time */
    int inputs_set_in_event_mode;                   /* an input was set in Co-Simulation Event Mode */
} fmi3_bridge;

#define BRIDGE(inst) ((fmi3_bridge *)(inst)->cb.componentEnvironment)

/* Intermediate Update Mode, by what the callback allows: after an accepted internal step the importer may
 * get values (intermediateVariableGetAllowed); where the solver needs the inputs inside a step it may set
 * them (intermediateVariableSetRequested), nothing else (the solver's state there is a trial stage) */
#define IU_GET 1
#define IU_SET 2

/* fmi2 names in the runtime's messages and what the FMI 3.0 importer called;
 * longest first where one name begins another; any other "fmi2" becomes
 * "fmi3" (fmi2DoStep, fmi2Terminate, fmi2Error ... have the same names). */
static const char *const renames[][2] = {
    {"fmi2GetRealOutputDerivatives", "fmi3GetOutputDerivatives"},
    {"fmi2GetRealStatus(fmi2LastSuccessfulTime)", "fmi3DoStep's lastSuccessfulTime"},
    {"fmi2GetReal", "fmi3GetFloat64"},
    {"fmi2SetReal", "fmi3SetFloat64"},
    {"fmi2GetInteger", "fmi3GetInt32"},
    {"fmi2SetInteger", "fmi3SetInt32"},
    {"fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives"},
    {"fmi2NewDiscreteStates", "fmi3UpdateDiscreteStates"},
    {"fmi2SetupExperiment", "fmi3EnterInitializationMode"},
    {"fmi2GetFMUstate", "fmi3GetFMUState"},
    {"fmi2SetFMUstate", "fmi3SetFMUState"},
    {"fmi2FreeFMUstate", "fmi3FreeFMUState"},
    {"fmi2SerializedFMUstateSize", "fmi3SerializedFMUStateSize"},
    {"fmi2SerializeFMUstate", "fmi3SerializeFMUState"},
    {"fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"},
    {"fmi2FMUstate", "fmi3FMUState"},
};

static void fmi3_text(const char *in, char *out, size_t n)
{
    size_t j = 0;
    while (*in && j + 1 < n) {
        if (in[0] == '%' && in[1] == '%') { /* fmugen_log doubled every '%' for a printf-style logger */
            out[j++] = '%';
            in += 2;
            continue;
        }
        /* an FMI name (fmi2DoStep, fmi2True): "fmi2" and a capital, so a variable named fmi2x stays */
        if (strncmp(in, "fmi2", 4) == 0 && in[4] >= 'A' && in[4] <= 'Z') {
            const char *to = "fmi3";
            size_t from_len = 4;
            for (size_t k = 0; k < sizeof renames / sizeof renames[0]; k++) {
                size_t l = strlen(renames[k][0]);
                if (strncmp(in, renames[k][0], l) == 0) {
                    to = renames[k][1];
                    from_len = l;
                    break;
                }
            }
            for (const char *t = to; *t && j + 1 < n; t++) out[j++] = *t;
            in += from_len;
            continue;
        }
        out[j++] = *in++;
    }
    out[j] = '\0';
}

/* The FMI 2.0 logger the runtime calls.  fmugen_log passes the finished text
 * as the format, with no arguments; the variadic part is never read. */
static void fmi2_to_fmi3_logger(fmi2ComponentEnvironment env, fmi2String instanceName, fmi2Status status,
                                fmi2String category, fmi2String message, ...)
{
    (void)instanceName; /* FMI 3.0's callback has no instance name: the environment identifies it */
    const fmi3_bridge *b = (const fmi3_bridge *)env;
    if (!b || !b->log) return;
    char text[4096];
    fmi3_text(message ? message : "", text, sizeof text);
    const fmi3Status s = status == fmi2Pending ? fmi3OK : (fmi3Status)status; /* the same order up to fmi2Fatal */
    b->log(b->env, s, category, text);
}

/* before an instance exists: straight to the importer's callback */
static void early_log(fmi3LogMessageCallback log, fmi3InstanceEnvironment env, const char *fmt, ...)
    FMUGEN_PRINTF(3, 4);
static void early_log(fmi3LogMessageCallback log, fmi3InstanceEnvironment env, const char *fmt, ...)
{
    if (!log) return;
    char text[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    log(env, fmi3Error, "logStatusError", text);
}

static fmi3Status st(fmi2Status s) { return s == fmi2Pending ? fmi3Error : (fmi3Status)s; }

/* a live instance of this runtime; a NULL or freed one has nobody to log to */
#define LIVE_OR_ERROR \
    if (!fmugen_live(INST)) return fmi3Error

/* Inside the intermediate-update callback (Intermediate Update Mode) the importer may only get values
 * after an accepted step (IU_GET), only set the inputs it named when setting is requested (IU_SET; see
 * fmi3SetFloat64): anything else -- above all a nested fmi3DoStep, or freeing the instance under the
 * running step -- is refused. */
static int in_update(fmugen_instance *inst, const char *fn)
{
    const int mode = BRIDGE(inst)->in_intermediate_update;
    if (!mode) return 0;
    if (mode == IU_SET)
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: not allowed in Intermediate Update Mode (inside the intermediate-update callback at t = "
                   "%.17g: intermediateVariableSetRequested is true, intermediateVariableGetAllowed false: only "
                   "setting the inputs named in requiredIntermediateVariables with fmi3SetFloat64 is allowed)",
                   fn, BRIDGE(inst)->iu_time);
    else
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: not allowed in Intermediate Update Mode (inside the intermediate-update callback at t = "
                   "%.17g: only getting values is allowed, intermediateVariableSetRequested is false)", fn,
                   inst->s.time);
    return 1;
}
#define NOT_IN_UPDATE_INST(inst, fn) \
    if (in_update((inst), (fn))) return fmi3Error
#define NOT_IN_UPDATE(fn) NOT_IN_UPDATE_INST(INST, fn)

/* fmugen_cs_ext.inputs_at: the inputs at t inside fmi3DoStep, set by the importer in the intermediate update
 * (FMI 3.0's replacement for FMI 2.0's input derivatives).  The callback comes where the solver needs u(t):
 * at every distinct time at which it evaluates the right-hand side (each Runge-Kutta stage, each Rosenbrock
 * stage and the time difference of its Jacobian, a trial step that is rejected afterwards), at the event
 * locator's times, at a sample instant and at the step's end -- not once per internal step at its start.
 * Inputs taken once per internal step and held over it would be a zero-order hold inside the step, an
 * error of O(h) in the inputs; taken at the stages, the solver integrates the ODE with the importer's
 * u(t) itself, as FMI 2.0's fmi2SetRealInputDerivatives lets it do with the polynomial: an importer that
 * sets the values of its extrapolation polynomial here gets the FMI 2.0 result to rounding, for every step
 * size and every polynomial degree.  The stages of one time share one callback (a Runge-Kutta method's
 * last stages, the first-same-as-last one, the finite-difference Jacobian): the importer's u is a function
 * of time.  intermediateStepFinished is false (a trial stage; never earlier than the last accepted step,
 * as the standard requires), intermediateVariableGetAllowed false (the state there is no solution point),
 * canReturnEarly false.  Inputs the importer does not set keep the last value set (the standard's rule):
 * at the step's start those set before fmi3DoStep, so an importer that sets nothing gets exactly the
 * held inputs of an FMU without the callback. */
static void intermediate_inputs(struct fmugen_ode *ode, double t, double *out)
{
    fmugen_instance *inst = ode->inst;
    fmi3_bridge *b = BRIDGE(inst);
    if (!b->iu_valid || t != b->iu_time) {
        fmi3Boolean requested = fmi3False;
        fmi3Float64 when = t;
        b->iu_time = t;
        b->in_intermediate_update = IU_SET;
        b->intermediate_update(b->env, t, fmi3True, fmi3False, fmi3False, fmi3False, &requested, &when);
        b->in_intermediate_update = 0;
        b->iu_valid = 1; /* earlyReturnRequested is ignored: canReturnEarly was false */
    }
    memcpy(out, b->iu_u, (size_t)inst->model->nu * sizeof(double));
}

/* fmi3SetFloat64 inside a set request: inputs named in requiredIntermediateVariables only, finite; they go
 * to the values the solver takes for iu_time (intermediate_inputs), not to the instance's inputs (which
 * fmi2DoStep sets from them at the step's end) */
static fmi3Status set_intermediate_inputs(fmugen_instance *inst, const fmi3ValueReference vr[], size_t n,
                                          const fmi3Float64 values[])
{
    const char *fn = "fmi3SetFloat64";
    const fmugen_model_def *m = inst->model;
    fmi3_bridge *b = BRIDGE(inst);
    char name[256];
    for (size_t i = 0; i < n; i++) { /* all checked first: a refused call sets nothing */
        const int input = vr[i] >= fmugen_vr_u(m) && vr[i] < fmugen_vr_y(m);
        if (!input || !b->iu_required[vr[i] - fmugen_vr_u(m)]) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: %s (value reference %u) cannot be set in Intermediate Update Mode (t = %.17g): %s", fn,
                       vr[i] < fmugen_vr_end(m) ? fmugen_real_name(inst, vr[i], name, sizeof name) : "<unknown>",
                       vr[i], b->iu_time,
                       input ? "it is not in requiredIntermediateVariables of fmi3InstantiateCoSimulation"
                             : "only inputs (intermediateUpdate=\"true\") may be set there");
            return fmi3Error;
        }
        if (!isfinite(values[i])) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: value %g for %s (value reference %u) at t = %.17g is not finite; rejected", fn,
                       values[i], fmugen_real_name(inst, vr[i], name, sizeof name), vr[i], b->iu_time);
            return fmi3Error;
        }
    }
    for (size_t i = 0; i < n; i++) b->iu_u[vr[i] - fmugen_vr_u(m)] = values[i];
    return fmi3OK;
}

/* fmugen_cs_ext.step_accepted: FMI 3.0's intermediate update after each accepted internal solver step
 * of fmi3DoStep (solver.h).  The importer may read every variable at the step's end (outputs computed
 * there with the inputs there, as fmi3DoStep gives them at a communication point) and may ask to return
 * early; the solver's state is not touched, so the step goes on exactly as without the callback.
 * Returns 1 when the solver is to stop now. */
static int intermediate_update(struct fmugen_ode *ode)
{
    fmugen_instance *inst = ode->inst;
    fmi3_bridge *b = BRIDGE(inst);
    fmugen_cs_ext *e = &b->ext;
    const double t = inst->s.time;
    /* the solvers move x in place and hold the inputs in their own buffer: what fmi3GetFloat64 reads */
    fmugen_ode_inputs(ode, t, inst->u);
    fmugen_invalidate(inst);
    const fmi3Boolean can = e->early_return_allowed && t < e->step_end ? fmi3True : fmi3False;
    fmi3Boolean requested = fmi3False;
    fmi3Float64 when = t;
    b->in_intermediate_update = IU_GET;
    /* intermediateVariableSetRequested false: inputs are taken where the solver needs them
     * (intermediate_inputs), not here; intermediateStepFinished true: this call comes only after accepted
     * steps, never for a trial */
    b->intermediate_update(b->env, t, fmi3False, fmi3True, fmi3True, can, &requested, &when);
    b->in_intermediate_update = 0;
    if (!requested) return 0;
    if (!can) { /* "only if canReturnEarly": an early return not allowed is not taken */
        fmugen_log(inst, fmi2OK, FMUGEN_LOG_EVENTS,
                   "fmi3DoStep: early return requested at t = %.17g ignored (canReturnEarly is false)", t);
        return 0;
    }
    if (!(when < e->step_end)) return 0; /* the step ends there anyway (NaN too) */
    e->stop_at = when > t ? when : t;   /* a time already passed: here */
    fmugen_log(inst, fmi2OK, FMUGEN_LOG_EVENTS, "fmi3DoStep: early return requested at t = %.17g for t = %.17g", t,
               e->stop_at);
    /* before the solver's own end: stop now (fmi2DoStep integrates on to a later stop_at); at or after it
     * fmi2DoStep stops there itself */
    return e->stop_at < e->target;
}

static int is_cs(const fmugen_instance *inst) { return inst->type == fmi2CoSimulation; }
/* a Co-Simulation instance with eventModeUsed = true */
static int cs_event_mode(const fmugen_instance *inst) { return is_cs(inst) && BRIDGE(inst)->ext.event_mode_used; }

static int refuse(fmugen_instance *inst, const char *fn, const char *why)
{
    fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: %s", fn, why);
    return 1;
}

/* ------------------------------------------------------------------------ */
/* inquiry, logging, creation and destruction                                */
/* ------------------------------------------------------------------------ */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    LIVE_OR_ERROR;
    return st(fmi2SetDebugLogging(instance, loggingOn ? fmi2True : fmi2False, nCategories, categories));
}

static fmi3Instance instantiate(const char *fn, fmi2Type type, fmi3String instanceName,
                                fmi3String instantiationToken, fmi3String resourcePath, fmi3Boolean visible,
                                fmi3Boolean loggingOn, fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                fmi3IntermediateUpdateCallback intermediateUpdate,
                                const fmi3ValueReference required[], size_t nRequired)
{
    if (!log) return NULL; /* nobody to tell why */
    fmi3_bridge *b = calloc(1, sizeof *b);
    if (!b) {
        early_log(log, env, "%s: out of memory", fn);
        return NULL;
    }
    b->log = log;
    b->env = env;
    /* FMI 3.0 has no memory callbacks: the runtime's calloc/free */
    fmi2CallbackFunctions cb = {fmi2_to_fmi3_logger, NULL, NULL, NULL, b};
    /* the instantiation token is the FMI 2.0 GUID: fmi2Instantiate refuses a mismatch, logged */
    fmugen_instance *inst = fmi2Instantiate(instanceName, type, instantiationToken, resourcePath, &cb,
                                            visible ? fmi2True : fmi2False, loggingOn ? fmi2True : fmi2False);
    if (!inst) {
        free(b);
        return NULL;
    }
    if (eventModeUsed && !fmugen_has_events(inst->model)) {
        /* hasEventMode is false for a model without events: the standard requires the error */
        early_log(log, env,
                  "%s: eventModeUsed = true, but hasEventMode is false in modelDescription.xml (the model has no "
                  "events: no state event, clause or sample clock)", fn);
        fmi2FreeInstance(inst);
        free(b);
        return NULL;
    }
    b->ext.event_mode_used = eventModeUsed ? 1 : 0;
    b->ext.early_return_allowed = earlyReturnAllowed ? 1 : 0;
    b->ext.stop_at = HUGE_VAL;
    b->intermediate_update = intermediateUpdate;
    b->ext.step_accepted = intermediateUpdate ? intermediate_update : NULL;
    /* inputs in requiredIntermediateVariables: the importer intends to set them in the intermediate update,
     * so the solver asks for them (intermediate_inputs); without one named, the callback never requests
     * setting, and the inputs are held over the step as without the callback */
    const fmugen_model_def *m = inst->model;
    int n_set = 0;
    if (intermediateUpdate && m->nu > 0 && required && nRequired > 0) {
        b->iu_required = calloc((size_t)m->nu, 1);
        b->iu_u = calloc((size_t)m->nu, sizeof(double));
        if (!b->iu_required || !b->iu_u) {
            early_log(log, env, "%s: out of memory", fn);
            fmi2FreeInstance(inst);
            free(b->iu_required);
            free(b->iu_u);
            free(b);
            return NULL;
        }
        for (size_t i = 0; i < nRequired; i++)
            if (required[i] >= fmugen_vr_u(m) && required[i] < fmugen_vr_y(m)) {
                n_set += !b->iu_required[required[i] - fmugen_vr_u(m)];
                b->iu_required[required[i] - fmugen_vr_u(m)] = 1;
            }
    }
    if (n_set > 0) {
        b->ext.inputs_at = intermediate_inputs;
    } else {
        free(b->iu_required);
        free(b->iu_u);
        b->iu_required = NULL;
        b->iu_u = NULL;
    }
    /* none of the three asked for: no extension, fmi2DoStep exactly as for FMI 2.0 */
    if (b->ext.event_mode_used || b->ext.early_return_allowed || intermediateUpdate) inst->cs_ext = &b->ext;
    return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    return instantiate("fmi3InstantiateModelExchange", fmi2ModelExchange, instanceName, instantiationToken,
                       resourcePath, visible, loggingOn, instanceEnvironment, logMessage, fmi3False, fmi3False,
                       NULL, NULL, 0);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    /* every variable may be read in the intermediate update after an accepted step, every input set when
     * setting is requested (intermediateUpdate = "true" on the outputs and inputs in modelDescription.xml):
     * the inputs named are those the solver asks for; other value references need no checking */
    return instantiate("fmi3InstantiateCoSimulation", fmi2CoSimulation, instanceName, instantiationToken,
                       resourcePath, visible, loggingOn, instanceEnvironment, logMessage, eventModeUsed,
                       earlyReturnAllowed, intermediateUpdate, requiredIntermediateVariables,
                       nRequiredIntermediateVariables);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    early_log(logMessage, instanceEnvironment,
              "fmi3InstantiateScheduledExecution: not supported (the FMU offers Model Exchange and Co-Simulation)");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    if (!fmugen_live(INST)) return; /* NULL or already freed: see fmi2FreeInstance */
    if (in_update(INST, "fmi3FreeInstance")) return; /* the step that called the callback still runs on it */
    fmi3_bridge *b = BRIDGE(INST);
    fmi2FreeInstance(instance);
    free(b->iu_required);
    free(b->iu_u);
    free(b);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3EnterInitializationMode");
    if (!fmugen_check_state(INST, FMUGEN_INSTANTIATED, "fmi3EnterInitializationMode")) return fmi3Error;
    fmi2Status s = fmi2SetupExperiment(instance, toleranceDefined ? fmi2True : fmi2False, tolerance, startTime,
                                       stopTimeDefined ? fmi2True : fmi2False, stopTime);
    if (s > fmi2Warning) return st(s);
    fmi2Status s2 = fmi2EnterInitializationMode(instance);
    return st(s2 > s ? s2 : s);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3ExitInitializationMode");
    fmi2Status s = fmi2ExitInitializationMode(instance);
    if (s <= fmi2Warning && cs_event_mode(INST)) {
        /* FMI 3.0: with eventModeUsed, Co-Simulation leaves initialisation into Event Mode (the initial
         * event iteration has run, as for FMI 2.0 Co-Simulation: fmi3UpdateDiscreteStates finds nothing
         * pending), and fmi3EnterStepMode goes on */
        INST->s.fmi_state = FMUGEN_EVENT_MODE;
        BRIDGE(INST)->inputs_set_in_event_mode = 0;
        fmugen_log(INST, fmi2OK, FMUGEN_LOG_EVENTS, "fmi3ExitInitializationMode: now in eventMode (eventModeUsed)");
    }
    return st(s);
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    LIVE_OR_ERROR;
    const char *fn = "fmi3EnterEventMode";
    NOT_IN_UPDATE(fn);
    if (!is_cs(INST)) return st(fmi2EnterEventMode(instance));
    if (!BRIDGE(INST)->ext.event_mode_used) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: this Co-Simulation instance was instantiated with eventModeUsed = false: it handles its "
                   "events inside fmi3DoStep, and the function must not be called", fn);
        return fmi3Error;
    }
    /* from Step Mode only (not after a discarded step: the state is the last good point, no event) */
    if (!fmugen_check_state(INST, FMUGEN_STEP_COMPLETE, fn)) return fmi3Error;
    INST->s.fmi_state = FMUGEN_EVENT_MODE;
    BRIDGE(INST)->inputs_set_in_event_mode = 0;
    fmugen_log(INST, fmi2OK, FMUGEN_LOG_EVENTS, "%s at t = %.17g%s", fn, INST->s.time,
               INST->s.cs_event_pending ? " (the event fmi3DoStep stopped at)" : "");
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3Terminate");
    return st(fmi2Terminate(instance));
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3Reset");
    BRIDGE(INST)->inputs_set_in_event_mode = 0;
    return st(fmi2Reset(instance)); /* clears s.cs_event_pending with the other scalars */
}

/* ------------------------------------------------------------------------ */
/* variables                                                                 */
/* ------------------------------------------------------------------------ */

/* value references of the event indicators and of the Int32 variables (see the top of the file) */
static fmi3ValueReference fmi3_z_base(const fmugen_model_def *m) { return fmugen_vr_end(m); }
static fmi3ValueReference fmi3_int_base(const fmugen_model_def *m) { return fmugen_vr_end(m) + (fmi3ValueReference)m->nz; }
static fmi3ValueReference fmi3_time_vr(const fmugen_model_def *m) { return fmi3_int_base(m) + FMUGEN_INT_COUNT; }

static int bad_arrays(fmugen_instance *inst, const char *fn, size_t nvr, const void *vr, size_t nValues,
                      const void *values)
{
    /* no arrays yet: one value per value reference */
    if (nValues != nvr) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: nValues = %zu but nValueReferences = %zu (this FMU has scalar variables only)", fn,
                   nValues, nvr);
        return 1;
    }
    if (nvr > 0 && (!vr || !values)) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: NULL array with %zu value references", fn, nvr);
        return 1;
    }
    return 0;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    LIVE_OR_ERROR;
    const char *fn = "fmi3GetFloat64";
    if (BRIDGE(INST)->in_intermediate_update == IU_SET && in_update(INST, fn)) return fmi3Error;
    if (!fmugen_check_state(INST, MASK_GET, fn)) return fmi3Error;
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    if (bad_arrays(inst, fn, nValueReferences, valueReferences, nValues, values)) return fmi3Error;
    int indicators = 0;
    for (size_t i = 0; i < nValueReferences; i++) {
        const fmi3ValueReference r = valueReferences[i];
        if (r >= fmi3_int_base(m) && r != fmi3_time_vr(m)) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: unknown value reference %u (Float64 variables are 0..%u and time %u)", fn, r,
                       fmi3_int_base(m) - 1u, fmi3_time_vr(m));
            return fmi3Error;
        }
        if (r >= fmi3_z_base(m)) indicators = 1;
    }
    if (!indicators) return st(fmi2GetReal(instance, valueReferences, nValueReferences, values));
    /* some are event indicators (or time): computed at the current point, the others one by one */
    double *z = calloc((size_t)m->nz + 1, sizeof *z);
    if (!z) return refuse(inst, fn, "out of memory"), fmi3Error;
    int rc = m->nz > 0 ? fmugen_event_indicators(inst, inst->s.time, inst->x, inst->u, z) : FMUGEN_OK;
    if (rc != FMUGEN_OK) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: the event indicators at t = %.17g failed: %s",
                   fn, inst->s.time, fmugen_model_status_text(rc));
        free(z);
        return fmi3Error;
    }
    fmi2Status worst = fmi2OK;
    for (size_t i = 0; i < nValueReferences && worst <= fmi2Warning; i++) {
        const fmi3ValueReference r = valueReferences[i];
        if (r == fmi3_time_vr(m)) {
            values[i] = inst->s.time;
        } else if (r >= fmi3_z_base(m)) {
            values[i] = z[r - fmi3_z_base(m)];
        } else {
            fmi2Status s = fmi2GetReal(instance, &valueReferences[i], 1, &values[i]);
            if (s > worst) worst = s;
        }
    }
    free(z);
    return st(worst);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    LIVE_OR_ERROR;
    const char *fn = "fmi3SetFloat64";
    if (BRIDGE(INST)->in_intermediate_update == IU_SET) { /* intermediateVariableSetRequested: inputs only */
        if (bad_arrays(INST, fn, nValueReferences, valueReferences, nValues, values)) return fmi3Error;
        return set_intermediate_inputs(INST, valueReferences, nValueReferences, values);
    }
    NOT_IN_UPDATE(fn);
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    if (bad_arrays(inst, fn, nValueReferences, valueReferences, nValues, values)) return fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++) {
        const fmi3ValueReference r = valueReferences[i];
        if (r == fmi3_time_vr(m)) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: cannot set time (value reference %u): the independent variable is set by "
                       "fmi3EnterInitializationMode, fmi3SetTime and fmi3DoStep", fn, r);
            return fmi3Error;
        }
        if (r >= fmi3_int_base(m)) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: unknown value reference %u (Float64 variables are 0..%u and time %u)", fn, r,
                       fmi3_int_base(m) - 1u, fmi3_time_vr(m));
            return fmi3Error;
        }
        if (r >= fmi3_z_base(m)) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: cannot set value reference %u: an event indicator is computed by the model", fn, r);
            return fmi3Error;
        }
    }
    fmi2Status s = fmi2SetReal(instance, valueReferences, nValueReferences, values);
    if (s <= fmi2Warning && nValueReferences > 0 && inst->s.fmi_state == FMUGEN_EVENT_MODE && is_cs(inst))
        BRIDGE(inst)->inputs_set_in_event_mode = 1; /* the event iteration sees them (fmi3UpdateDiscreteStates) */
    return st(s);
}

/* Int32 value references -> the FMI 2.0 Integer ones in buf (NULL after a logged refusal) */
static fmi2ValueReference *int_refs(fmugen_instance *inst, const char *fn, const fmi3ValueReference vr[], size_t nvr)
{
    const fmi3ValueReference base = fmi3_int_base(inst->model);
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] < base || vr[i] - base >= FMUGEN_INT_COUNT) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: unknown value reference %u (Int32 variables are %u..%u)", fn, vr[i], base,
                       base + FMUGEN_INT_COUNT - 1u);
            return NULL;
        }
    }
    fmi2ValueReference *buf = calloc(nvr + 1, sizeof *buf);
    if (!buf) {
        refuse(inst, fn, "out of memory");
        return NULL;
    }
    for (size_t i = 0; i < nvr; i++) buf[i] = vr[i] - base;
    return buf;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Int32 values[], size_t nValues)
{
    LIVE_OR_ERROR;
    const char *fn = "fmi3GetInt32";
    if (BRIDGE(INST)->in_intermediate_update == IU_SET && in_update(INST, fn)) return fmi3Error;
    if (!fmugen_check_state(INST, MASK_GET, fn)) return fmi3Error;
    if (bad_arrays(INST, fn, nValueReferences, valueReferences, nValues, values)) return fmi3Error;
    fmi2ValueReference *vr = int_refs(INST, fn, valueReferences, nValueReferences);
    if (!vr) return fmi3Error;
    fmi2Integer *v = calloc(nValueReferences + 1, sizeof *v);
    fmi2Status s = fmi2Error;
    if (v) {
        s = fmi2GetInteger(instance, vr, nValueReferences, v);
        if (s <= fmi2Warning)
            for (size_t i = 0; i < nValueReferences; i++) values[i] = (fmi3Int32)v[i];
    } else {
        refuse(INST, fn, "out of memory");
    }
    free(v);
    free(vr);
    return st(s);
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Int32 values[], size_t nValues)
{
    LIVE_OR_ERROR;
    const char *fn = "fmi3SetInt32";
    NOT_IN_UPDATE(fn);
    if (bad_arrays(INST, fn, nValueReferences, valueReferences, nValues, values)) return fmi3Error;
    fmi2ValueReference *vr = int_refs(INST, fn, valueReferences, nValueReferences);
    if (!vr) return fmi3Error;
    fmi2Integer *v = calloc(nValueReferences + 1, sizeof *v);
    fmi2Status s = fmi2Error;
    if (v) {
        for (size_t i = 0; i < nValueReferences; i++) v[i] = (fmi2Integer)values[i];
        s = fmi2SetInteger(instance, vr, nValueReferences, v);
    } else {
        refuse(INST, fn, "out of memory");
    }
    free(v);
    free(vr);
    return st(s);
}

/* The types the FMU has no variables of: no value reference is known; an
 * empty call is a valid no-op. */
static fmi3Status no_variables(fmi3Instance instance, const char *fn, const fmi3ValueReference vr[], size_t nvr)
{
    LIVE_OR_ERROR;
    if (nvr == 0) return fmi3OK;
    fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
               "%s: unknown value reference %u (this FMU has no variables of that type)", fn, vr ? vr[0] : 0u);
    return fmi3Error;
}

#define NO_VARIABLES(name, ctype)                                                                            \
    fmi3Status fmi3Get##name(fmi3Instance instance, const fmi3ValueReference valueReferences[],              \
                             size_t nValueReferences, ctype values[], size_t nValues)                         \
    {                                                                                                        \
        (void)values, (void)nValues;                                                                         \
        return no_variables(instance, "fmi3Get" #name, valueReferences, nValueReferences);                   \
    }                                                                                                        \
    fmi3Status fmi3Set##name(fmi3Instance instance, const fmi3ValueReference valueReferences[],              \
                             size_t nValueReferences, const ctype values[], size_t nValues)                   \
    {                                                                                                        \
        (void)values, (void)nValues;                                                                         \
        return no_variables(instance, "fmi3Set" #name, valueReferences, nValueReferences);                   \
    }

NO_VARIABLES(Float32, fmi3Float32)
NO_VARIABLES(Int8, fmi3Int8)
NO_VARIABLES(UInt8, fmi3UInt8)
NO_VARIABLES(Int16, fmi3Int16)
NO_VARIABLES(UInt16, fmi3UInt16)
NO_VARIABLES(UInt32, fmi3UInt32)
NO_VARIABLES(Int64, fmi3Int64)
NO_VARIABLES(UInt64, fmi3UInt64)
NO_VARIABLES(Boolean, fmi3Boolean)
NO_VARIABLES(String, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)valueSizes, (void)values, (void)nValues;
    return no_variables(instance, "fmi3GetBinary", valueReferences, nValueReferences);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    (void)valueSizes, (void)values, (void)nValues;
    return no_variables(instance, "fmi3SetBinary", valueReferences, nValueReferences);
}

/* ------------------------------------------------------------------------ */
/* not supported                                                             */
/* ------------------------------------------------------------------------ */

static fmi3Status unsupported(fmi3Instance instance, const char *fn, const char *why)
{
    LIVE_OR_ERROR;
    fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: not supported by this FMU (%s)", fn, why);
    return fmi3Error;
}

#define NO_CLOCKS "it has no clocks"

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[])
{
    (void)valueReferences, (void)nValueReferences, (void)values;
    return unsupported(instance, "fmi3GetClock", NO_CLOCKS);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[])
{
    (void)valueReferences, (void)nValueReferences, (void)values;
    return unsupported(instance, "fmi3SetClock", NO_CLOCKS);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference, (void)nDependencies;
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies",
                       "the dependencies are in modelDescription.xml's <ModelStructure>");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent, (void)elementIndicesOfDependent, (void)independents, (void)elementIndicesOfIndependents;
    (void)dependencyKinds, (void)nDependencies;
    return unsupported(instance, "fmi3GetVariableDependencies",
                       "the dependencies are in modelDescription.xml's <ModelStructure>");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    return unsupported(instance, "fmi3GetAdjointDerivative", "providesAdjointDerivatives is false");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    return unsupported(instance, "fmi3EnterConfigurationMode", "it has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    return unsupported(instance, "fmi3ExitConfigurationMode", "it has no structural parameters");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences, (void)nValueReferences, (void)intervals, (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalDecimal", NO_CLOCKS);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions, (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalFraction", NO_CLOCKS);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    return unsupported(instance, "fmi3GetShiftDecimal", NO_CLOCKS);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return unsupported(instance, "fmi3GetShiftFraction", NO_CLOCKS);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    (void)valueReferences, (void)nValueReferences, (void)intervals;
    return unsupported(instance, "fmi3SetIntervalDecimal", NO_CLOCKS);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return unsupported(instance, "fmi3SetIntervalFraction", NO_CLOCKS);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    return unsupported(instance, "fmi3SetShiftDecimal", NO_CLOCKS);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return unsupported(instance, "fmi3SetShiftFraction", NO_CLOCKS);
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    return unsupported(instance, "fmi3EvaluateDiscreteStates", "providesEvaluateDiscreteStates is false");
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    LIVE_OR_ERROR;
    const char *fn = "fmi3EnterStepMode";
    NOT_IN_UPDATE(fn);
    if (!cs_event_mode(INST)) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: only for a Co-Simulation instance with eventModeUsed = true (%s)", fn,
                   is_cs(INST) ? "this one is in Step Mode from fmi3ExitInitializationMode on"
                               : "this is a Model Exchange instance");
        return fmi3Error;
    }
    if (!fmugen_check_state(INST, FMUGEN_EVENT_MODE, fn)) return fmi3Error;
    if (INST->s.cs_event_pending) {
        /* leaving it would step on from the state just before the event's update (a ball below ground) */
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: the event at t = %.17g that fmi3DoStep stopped at is not handled yet: call "
                   "fmi3UpdateDiscreteStates first", fn, INST->s.time);
        return fmi3Error;
    }
    INST->s.fmi_state = FMUGEN_STEP_COMPLETE;
    fmugen_log(INST, fmi2OK, FMUGEN_LOG_EVENTS, "%s at t = %.17g", fn, INST->s.time);
    return fmi3OK;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference, (void)activationTime;
    return unsupported(instance, "fmi3ActivateModelPartition", "Scheduled Execution is not supported");
}

/* ------------------------------------------------------------------------ */
/* FMU state and directional derivatives                                    */
/* ------------------------------------------------------------------------ */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3GetFMUState");
    return st(fmi2GetFMUstate(instance, (fmi2FMUstate *)FMUState));
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3SetFMUState");
    return st(fmi2SetFMUstate(instance, FMUState));
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3FreeFMUState");
    return st(fmi2FreeFMUstate(instance, (fmi2FMUstate *)FMUState));
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3SerializedFMUStateSize");
    return st(fmi2SerializedFMUstateSize(instance, FMUState, size));
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3SerializeFMUState");
    return st(fmi2SerializeFMUstate(instance, FMUState, (fmi2Byte *)serializedState, size));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    LIVE_OR_ERROR;
    NOT_IN_UPDATE("fmi3DeserializeFMUState");
    return st(fmi2DeSerializeFMUstate(instance, (const fmi2Byte *)serializedState, size, (fmi2FMUstate *)FMUState));
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    LIVE_OR_ERROR;
    const char *fn = "fmi3GetDirectionalDerivative";
    NOT_IN_UPDATE(fn); /* forbidden in Intermediate Update Mode */
    if (nSeed != nKnowns || nSensitivity != nUnknowns) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: nSeed = %zu, nKnowns = %zu, nSensitivity = %zu, nUnknowns = %zu: this FMU has scalar "
                   "variables only, so nSeed must equal nKnowns and nSensitivity nUnknowns",
                   fn, nSeed, nKnowns, nSensitivity, nUnknowns);
        return fmi3Error;
    }
    return st(fmi2GetDirectionalDerivative(instance, unknowns, nUnknowns, knowns, nKnowns, seed, sensitivity));
}

/* ------------------------------------------------------------------------ */
/* Model Exchange                                                            */
/* ------------------------------------------------------------------------ */

/* Co-Simulation Event Mode: the whole event iteration in one call (discreteStatesNeedUpdate is false
 * after it), the one fmi2DoStep runs inside a step without Event Mode (fmugen_cs_event_update). */
static fmi3Status cs_update_discrete_states(fmugen_instance *inst, fmi3Boolean *discreteStatesNeedUpdate,
                                            fmi3Boolean *terminateSimulation,
                                            fmi3Boolean *nominalsOfContinuousStatesChanged,
                                            fmi3Boolean *valuesOfContinuousStatesChanged,
                                            fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime)
{
    const char *fn = "fmi3UpdateDiscreteStates";
    const fmugen_model_def *m = inst->model;
    NOT_IN_UPDATE_INST(inst, fn);
    if (!BRIDGE(inst)->ext.event_mode_used) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: this Co-Simulation instance was instantiated with eventModeUsed = false: it has no Event "
                   "Mode (fmi3DoStep handles the events)", fn);
        return fmi3Error;
    }
    if (!fmugen_check_state(inst, FMUGEN_EVENT_MODE, fn)) return fmi3Error;
    double *x0 = calloc((size_t)m->nx + 1, sizeof *x0);
    if (!x0) return refuse(inst, fn, "out of memory"), fmi3Error;
    if (m->nx) memcpy(x0, inst->x, (size_t)m->nx * sizeof(double));
    char msg[600];
    int rc = fmugen_cs_event_update(inst, fn, BRIDGE(inst)->inputs_set_in_event_mode, msg, sizeof msg);
    BRIDGE(inst)->inputs_set_in_event_mode = 0;
    int x_changed = 0;
    for (int i = 0; i < m->nx; i++) x_changed |= x0[i] != inst->x[i];
    free(x0);
    if (rc != FMUGEN_OK) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: %s", fn, msg);
        return fmi3Error;
    }
    fmugen_invalidate(inst);
    if (fmugen_evaluate_cached(inst, fn) != FMUGEN_OK) return fmi3Error; /* outputs after the event, checked */
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = x_changed ? fmi3True : fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    if (m->ns) { /* the next sample instant: a time event the importer may plan its steps to */
        double next;
        int at;
        if (fmugen_next_tick(inst, inst->s.time, &next, &at) == FMUGEN_OK && isfinite(next)) {
            *nextEventTimeDefined = fmi3True;
            *nextEventTime = next;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    LIVE_OR_ERROR;
    if (!discreteStatesNeedUpdate || !terminateSimulation || !nominalsOfContinuousStatesChanged ||
        !valuesOfContinuousStatesChanged || !nextEventTimeDefined || !nextEventTime)
        return refuse(INST, "fmi3UpdateDiscreteStates", "an output argument is NULL"), fmi3Error;
    if (is_cs(INST))
        return cs_update_discrete_states(INST, discreteStatesNeedUpdate, terminateSimulation,
                                         nominalsOfContinuousStatesChanged, valuesOfContinuousStatesChanged,
                                         nextEventTimeDefined, nextEventTime);
    fmi2EventInfo ei;
    memset(&ei, 0, sizeof ei);
    fmi2Status s = fmi2NewDiscreteStates(instance, &ei);
    if (s > fmi2Warning) return st(s);
    *discreteStatesNeedUpdate = ei.newDiscreteStatesNeeded ? fmi3True : fmi3False;
    *terminateSimulation = ei.terminateSimulation ? fmi3True : fmi3False;
    *nominalsOfContinuousStatesChanged = ei.nominalsOfContinuousStatesChanged ? fmi3True : fmi3False;
    *valuesOfContinuousStatesChanged = ei.valuesOfContinuousStatesChanged ? fmi3True : fmi3False;
    *nextEventTimeDefined = ei.nextEventTimeDefined ? fmi3True : fmi3False;
    *nextEventTime = ei.nextEventTime;
    return st(s);
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    LIVE_OR_ERROR;
    return st(fmi2EnterContinuousTimeMode(instance));
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    LIVE_OR_ERROR;
    if (!enterEventMode || !terminateSimulation)
        return refuse(INST, "fmi3CompletedIntegratorStep", "enterEventMode or terminateSimulation is NULL"),
               fmi3Error;
    fmi2Boolean enter = fmi2False, term = fmi2False;
    fmi2Status s = fmi2CompletedIntegratorStep(instance, noSetFMUStatePriorToCurrentPoint ? fmi2True : fmi2False,
                                               &enter, &term);
    *enterEventMode = enter ? fmi3True : fmi3False;
    *terminateSimulation = term ? fmi3True : fmi3False;
    return st(s);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    LIVE_OR_ERROR;
    return st(fmi2SetTime(instance, time));
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    LIVE_OR_ERROR;
    return st(fmi2SetContinuousStates(instance, continuousStates, nContinuousStates));
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    LIVE_OR_ERROR;
    return st(fmi2GetDerivatives(instance, derivatives, nContinuousStates));
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    LIVE_OR_ERROR;
    return st(fmi2GetEventIndicators(instance, eventIndicators, nEventIndicators));
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    LIVE_OR_ERROR;
    return st(fmi2GetContinuousStates(instance, continuousStates, nContinuousStates));
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates)
{
    LIVE_OR_ERROR;
    return st(fmi2GetNominalsOfContinuousStates(instance, nominals, nContinuousStates));
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    LIVE_OR_ERROR;
    if (!nEventIndicators) return refuse(INST, "fmi3GetNumberOfEventIndicators", "nEventIndicators is NULL"), fmi3Error;
    *nEventIndicators = (size_t)INST->model->nz;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    LIVE_OR_ERROR;
    if (!nContinuousStates)
        return refuse(INST, "fmi3GetNumberOfContinuousStates", "nContinuousStates is NULL"), fmi3Error;
    *nContinuousStates = (size_t)INST->model->nx;
    return fmi3OK;
}

/* ------------------------------------------------------------------------ */
/* Co-Simulation                                                             */
/* ------------------------------------------------------------------------ */

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    LIVE_OR_ERROR;
    const char *fn = "fmi3GetOutputDerivatives";
    if (bad_arrays(INST, fn, nValueReferences, valueReferences, nValues, values)) return fmi3Error;
    if (nValueReferences > 0 && !orders) return refuse(INST, fn, "orders is NULL"), fmi3Error;
    fmi2Integer *o = calloc(nValueReferences + 1, sizeof *o);
    if (!o) return refuse(INST, fn, "out of memory"), fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++) o[i] = (fmi2Integer)orders[i];
    fmi2Status s = fmi2GetRealOutputDerivatives(instance, valueReferences, nValueReferences, o, values);
    free(o);
    return st(s);
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    LIVE_OR_ERROR;
    const char *fn = "fmi3DoStep";
    NOT_IN_UPDATE(fn); /* a step inside the callback of the running one */
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
        return refuse(INST, fn, "an output argument is NULL"), fmi3Error;
    if (INST->s.cs_event_pending && INST->s.fmi_state == FMUGEN_STEP_COMPLETE) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: the last fmi3DoStep returned eventHandlingNeeded = true at t = %.17g: call "
                   "fmi3EnterEventMode and fmi3UpdateDiscreteStates before the next step", fn, INST->s.time);
        return fmi3Error;
    }
    fmi3_bridge *b = BRIDGE(INST);
    if (b->ext.inputs_at) { /* the inputs set before the step are those until the importer sets others */
        memcpy(b->iu_u, INST->u, (size_t)INST->model->nu * sizeof(double));
        b->iu_valid = 0;
    }
    fmi2Status s = fmi2DoStep(instance, currentCommunicationPoint, communicationStepSize,
                              noSetFMUStatePriorToCurrentPoint ? fmi2True : fmi2False);
    /* without eventModeUsed events are handled inside the step; with it, an event ends the step
     * (earlyReturnAllowed) or, at the step's end, waits there for the importer's Event Mode */
    const fmugen_cs_ext *e = INST->cs_ext;
    *eventHandlingNeeded = s <= fmi2Warning && INST->s.cs_event_pending ? fmi3True : fmi3False;
    *earlyReturn = s <= fmi2Warning && e && e->returned_early ? fmi3True : fmi3False;
    fmi2Boolean terminated = fmi2False;
    if (s <= fmi2Discard && fmi2GetBooleanStatus(instance, fmi2Terminated, &terminated) != fmi2OK)
        terminated = fmi2False;
    *terminateSimulation = terminated ? fmi3True : fmi3False;
    *lastSuccessfulTime = INST->s.last_successful_time;
    return st(s);
}
