/*
 * fmi2_functions.c -- the model-agnostic FMI 2.0 runtime of fmugen: the
 * functions common to Model Exchange (ME) and Co-Simulation (CS).  ME-only
 * functions are in fmi2_model_exchange.c, CS-only ones in
 * fmi2_co_simulation.c, FMU state and its serialisation in fmu_state.c, the
 * CS solvers in solver_*.c.  All entry points are exported unprefixed (no
 * FMI2_FUNCTION_PREFIX), with the declarations of the standard headers.
 *
 * States (FMI 2.0 sec. 3.2.3 and 4.2.4):
 *   instantiated, initializationMode, eventMode (ME), continuousTimeMode (ME),
 *   stepComplete (CS), stepFailed (CS, after fmi2DoStep returned fmi2Discard),
 *   terminated, error.  The runtime never returns fmi2Pending, so CS is never
 *   in stepInProgress.
 *
 * Which function may be called in which state (a call in another state
 * returns fmi2Error, logs "<function>: not allowed in state <state>" and
 * changes nothing):
 *   fmi2GetTypesPlatform, fmi2GetVersion          always
 *   fmi2Instantiate                               (creates: -> instantiated)
 *   fmi2FreeInstance, fmi2Reset (-> instantiated), fmi2SetDebugLogging,
 *   fmi2GetFMUstate, fmi2SetFMUstate, fmi2FreeFMUstate,
 *   fmi2SerializedFMUstateSize, fmi2SerializeFMUstate,
 *   fmi2DeSerializeFMUstate                       every state
 *   fmi2SetupExperiment                           instantiated
 *   fmi2EnterInitializationMode                   instantiated -> initializationMode
 *   fmi2ExitInitializationMode                    initializationMode -> eventMode (ME) / stepComplete (CS)
 *   fmi2Terminate                                 eventMode, continuousTimeMode, stepComplete, stepFailed -> terminated
 *   fmi2GetReal/Integer/Boolean/String,
 *   fmi2GetDirectionalDerivative                  initializationMode, eventMode, continuousTimeMode,
 *                                                 stepComplete, stepFailed, terminated, error
 *   fmi2SetReal                                   instantiated, initializationMode, eventMode,
 *                                                 continuousTimeMode, stepComplete
 *   fmi2SetInteger/Boolean/String                 instantiated, initializationMode, eventMode, stepComplete
 *     per variable: parameters (p, the runtime parameters rtol, atol,
 *     max_step, fixed_step, solver; all variability fixed) and state start
 *     values only in instantiated and initializationMode; inputs in every
 *     state above; derivatives, outputs and the solver counters never.
 *   ME only:
 *   fmi2EnterEventMode                            eventMode, continuousTimeMode -> eventMode
 *   fmi2NewDiscreteStates                         eventMode
 *   fmi2EnterContinuousTimeMode                   eventMode -> continuousTimeMode
 *   fmi2CompletedIntegratorStep                   continuousTimeMode
 *   fmi2SetTime                                   eventMode, continuousTimeMode
 *   fmi2SetContinuousStates                       continuousTimeMode
 *   fmi2GetDerivatives                            eventMode, continuousTimeMode, terminated, error
 *   fmi2GetEventIndicators, fmi2GetContinuousStates
 *                                                 initializationMode, eventMode, continuousTimeMode,
 *                                                 terminated, error
 *   fmi2GetNominalsOfContinuousStates             instantiated, eventMode, continuousTimeMode,
 *                                                 terminated, error
 *   CS only:
 *   fmi2SetRealInputDerivatives                   instantiated, initializationMode, stepComplete
 *   fmi2GetRealOutputDerivatives                  stepComplete, stepFailed, terminated, error
 *   fmi2DoStep                                    stepComplete -> stepComplete, or stepFailed on fmi2Discard
 *   fmi2CancelStep                                stepInProgress (never reached: always fmi2Error)
 *   fmi2GetStatus/RealStatus/IntegerStatus/BooleanStatus/StringStatus
 *                                                 stepComplete, stepFailed, terminated
 * An ME function called on a CS instance (or the reverse) returns fmi2Error.
 *
 * Log categories (declare them in modelDescription.xml in this order):
 *   logEvents, logStatusWarning, logStatusError, logAll.
 * Messages of status warning and worse always go to the logger; fmi2OK
 * messages only when debug logging is on for their category or logAll.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmugen_runtime.h"
#include "solver.h"

#define ANY_STATE                                                                                     \
    (FMUGEN_INSTANTIATED | FMUGEN_INITIALIZATION_MODE | FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | \
     FMUGEN_STEP_COMPLETE | FMUGEN_STEP_FAILED | FMUGEN_TERMINATED | FMUGEN_ERROR)
#define MASK_GET                                                                                      \
    (FMUGEN_INITIALIZATION_MODE | FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | FMUGEN_STEP_COMPLETE | \
     FMUGEN_STEP_FAILED | FMUGEN_TERMINATED | FMUGEN_ERROR)
#define MASK_SET_REAL                                                                                 \
    (FMUGEN_INSTANTIATED | FMUGEN_INITIALIZATION_MODE | FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | \
     FMUGEN_STEP_COMPLETE)
#define MASK_SET_OTHER \
    (FMUGEN_INSTANTIATED | FMUGEN_INITIALIZATION_MODE | FMUGEN_EVENT_MODE | FMUGEN_STEP_COMPLETE)
#define MASK_BEFORE_INIT_END (FMUGEN_INSTANTIATED | FMUGEN_INITIALIZATION_MODE)

#define INST ((fmugen_instance *)c)
#define CHECK_STATE(mask, fn) \
    if (!fmugen_check_state(INST, (mask), (fn))) return fmi2Error

/* ------------------------------------------------------------------------ */
/* inquiry and logging                                                       */
/* ------------------------------------------------------------------------ */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    CHECK_STATE(ANY_STATE, "fmi2SetDebugLogging");
    if (nCategories > 0 && !categories) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2SetDebugLogging: categories[] is NULL");
        return fmi2Error;
    }
    /* check all names first so that a bad call changes nothing */
    for (size_t i = 0; i < nCategories; i++) {
        int found = 0;
        for (int k = 0; k < FMUGEN_LOG_COUNT; k++)
            if (categories[i] && strcmp(categories[i], fmugen_log_category_names[k]) == 0) found = 1;
        if (!found) {
            fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2SetDebugLogging: unknown log category \"%s\" (known: logEvents, logStatusWarning, "
                       "logStatusError, logAll)", categories[i] ? categories[i] : "(null)");
            return fmi2Error;
        }
    }
    INST->logging_on = loggingOn ? 1 : 0;
    if (nCategories == 0) {
        for (int k = 0; k < FMUGEN_LOG_COUNT; k++) INST->log_category_on[k] = INST->logging_on;
    } else {
        for (size_t i = 0; i < nCategories; i++)
            for (int k = 0; k < FMUGEN_LOG_COUNT; k++)
                if (strcmp(categories[i], fmugen_log_category_names[k]) == 0)
                    INST->log_category_on[k] = INST->logging_on;
    }
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* creation and destruction                                                  */
/* ------------------------------------------------------------------------ */

static void *rt_alloc(const fmi2CallbackFunctions *cb, size_t n, size_t size)
{
    return cb->allocateMemory ? cb->allocateMemory(n, size) : calloc(n, size);
}

static void rt_free(const fmi2CallbackFunctions *cb, void *p)
{
    if (!p) return;
    if (cb->freeMemory) cb->freeMemory(p);
    else free(p);
}

void fmi2FreeInstance(fmi2Component c)
{
    fmugen_instance *inst = INST;
    /* NULL, or an instance already freed (its tag cleared below; if its
     * memory has been reused since, the tag is most likely gone as well):
     * nothing to free, and nothing safe to log to */
    if (!fmugen_live(inst)) return;
    inst->tag = 0;
    fmi2CallbackFunctions cb = inst->cb;
    rt_free(&cb, inst->step_start);
    rt_free(&cb, inst->vec);
    rt_free(&cb, inst->ev_work);
    rt_free(&cb, inst->dx_cache);
    rt_free(&cb, inst->y_cache);
    rt_free(&cb, inst->work);
    rt_free(&cb, inst->ipiv);
    rt_free(&cb, inst->instance_name);
    rt_free(&cb, inst);
}

/* Sanity of the generated model struct: a broken generator must not crash
 * the importer. */
static const char *model_problem(const fmugen_model_def *m)
{
    if (m->nx < 0 || m->nu < 0 || m->ny < 0 || m->np < 0) return "negative sizes";
    if (!m->evaluate) return "evaluate is NULL";
    if (m->has_jacobian && !m->jacobian) return "has_jacobian is set but jacobian is NULL";
    if (m->nx && (!m->x_start || !m->x_nominal || !m->x_names)) return "x_start, x_nominal or x_names is NULL";
    if (m->nu && (!m->u_start || !m->u_names)) return "u_start or u_names is NULL";
    if (m->ny && !m->y_names) return "y_names is NULL";
    if (m->np && (!m->p_start || !m->p_names)) return "p_start or p_names is NULL";
    for (int i = 0; i < m->nx; i++)
        if (!(m->x_nominal[i] > 0) || !isfinite(m->x_nominal[i])) return "a nominal value is not positive";
    if (m->solver_start < 0 || m->solver_start > FMUGEN_SOLVER_RK4) return "solver_start is not a solver";
    if (m->rt_start)
        for (int i = 0; i < FMUGEN_RT_COUNT; i++)
            if (!(m->rt_start[i] >= 0) || !isfinite(m->rt_start[i])) return "a runtime start value is negative";
    for (int i = 0; i < m->np; i++)
        if ((m->p_min && !(m->p_start[i] >= m->p_min[i])) || (m->p_max && !(m->p_start[i] <= m->p_max[i])))
            return "a parameter's start value is outside its range";
    if (m->nz < 0 || m->nd < 0 || m->ng < 0 || m->na < 0) return "negative event sizes";
    if (m->nz && !m->indicators) return "nz > 0 but indicators is NULL";
    if (m->nd && (!m->d_start || !m->d_names)) return "d_start or d_names is NULL";
    if (m->ng && (!m->update || (m->na && (!m->assign_clause || !m->assign_target))))
        return "ng > 0 but update, assign_clause or assign_target is NULL";
    for (int a = 0; a < m->na; a++)
        if (m->assign_clause[a] < 0 || m->assign_clause[a] >= m->ng || m->assign_target[a] < 0 ||
            m->assign_target[a] >= m->nd + m->nx)
            return "an event assignment names no clause or no target";
    if (m->ns < 0 || (m->ns && (!m->clocks || !m->clock_tick))) return "ns > 0 but clocks or clock_tick is NULL";
    for (int k = 0; k < m->ns; k++)
        if (m->clock_tick[k] < 0 || m->clock_tick[k] >= m->nd) return "a clock's tick flag is no discrete state";
    return NULL;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->logger) return NULL; /* nobody to tell why */
    const fmugen_model_def *m = &fmugen_model;
    /* a temporary instance only for logging before the real one exists */
    fmugen_instance tmp;
    memset(&tmp, 0, sizeof tmp);
    tmp.cb = *functions;
    tmp.instance_name = (char *)(instanceName ? instanceName : "?");
    if (!instanceName || !instanceName[0]) {
        fmugen_log(&tmp, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2Instantiate: instanceName is NULL or empty");
        return NULL;
    }
    if (fmuType != fmi2ModelExchange && fmuType != fmi2CoSimulation) {
        fmugen_log(&tmp, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2Instantiate: fmuType %d is neither fmi2ModelExchange nor fmi2CoSimulation", (int)fmuType);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, m->guid) != 0) {
        fmugen_log(&tmp, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2Instantiate: GUID \"%s\" does not match this FMU's \"%s\"", fmuGUID ? fmuGUID : "(null)",
                   m->guid);
        return NULL;
    }
    const char *problem = model_problem(m);
    if (problem) {
        fmugen_log(&tmp, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2Instantiate: invalid model definition: %s",
                   problem);
        return NULL;
    }
    fmugen_instance *inst = rt_alloc(functions, 1, sizeof *inst);
    if (!inst) {
        fmugen_log(&tmp, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2Instantiate: out of memory");
        return NULL;
    }
    memset(inst, 0, sizeof *inst);
    inst->tag = FMUGEN_INSTANCE_TAG;
    inst->model = m;
    inst->type = fmuType;
    inst->cb = *functions;
    inst->logging_on = loggingOn ? 1 : 0;
    for (int k = 0; k < FMUGEN_LOG_COUNT; k++) inst->log_category_on[k] = inst->logging_on;
    size_t len = strlen(instanceName);
    inst->instance_name = rt_alloc(functions, len + 1, 1);
    const int nx = m->nx, nu = m->nu, ny = m->ny, np = m->np, nd = m->nd, nz = m->nz;
    inst->n_vec = (size_t)(2 * nx + 4 * nu + np + nd + nz);
    inst->vec = rt_alloc(functions, inst->n_vec + 1, sizeof(double));
    inst->dx_cache = rt_alloc(functions, (size_t)nx + 1, sizeof(double));
    inst->y_cache = rt_alloc(functions, (size_t)ny + 1, sizeof(double));
    inst->work = rt_alloc(functions, fmugen_workspace_doubles(nx, nu), sizeof(double));
    inst->ipiv = rt_alloc(functions, (size_t)nx + 1, sizeof(int));
    inst->step_start = rt_alloc(functions, inst->n_vec + 1, sizeof(double));
    inst->ev_work = rt_alloc(functions, 5 * (size_t)nx + 3 * (size_t)nz + (size_t)m->ng + (size_t)m->na +
                             2 * (size_t)m->ns + 1, sizeof(double));
    if (!inst->instance_name || !inst->vec || !inst->dx_cache || !inst->y_cache || !inst->work || !inst->ipiv ||
        !inst->step_start || !inst->ev_work) {
        fmugen_log(&tmp, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2Instantiate: out of memory");
        fmi2FreeInstance(inst);
        return NULL;
    }
    memcpy(inst->instance_name, instanceName, len + 1);
    inst->x = inst->vec;
    inst->u = inst->x + nx;
    inst->du = inst->u + nu;
    inst->ddu = inst->du + nu;
    inst->dddu = inst->ddu + nu;
    inst->p = inst->dddu + nu;
    inst->fsal = inst->p + np + nd;
    inst->zpre = inst->fsal + nx;
    fmugen_set_defaults(inst);
    fmugen_log(inst, fmi2OK, FMUGEN_LOG_EVENTS, "fmi2Instantiate: %s instance of %s (nx=%d, nu=%d, ny=%d, np=%d)",
               fmuType == fmi2ModelExchange ? "Model Exchange" : "Co-Simulation", m->model_identifier, nx, nu,
               ny, np);
    return inst;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    CHECK_STATE(FMUGEN_INSTANTIATED, "fmi2SetupExperiment");
    if (!isfinite(startTime)) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2SetupExperiment: startTime %g is not finite",
                   startTime);
        return fmi2Error;
    }
    if (stopTimeDefined && !(stopTime >= startTime)) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2SetupExperiment: stopTime %g is before startTime %g", stopTime, startTime);
        return fmi2Error;
    }
    if (toleranceDefined && !(tolerance > 0 && tolerance < 1)) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2SetupExperiment: tolerance %g must lie in (0, 1)", tolerance);
        return fmi2Error;
    }
    INST->s.time = startTime;
    INST->s.start_time = startTime;
    INST->s.last_successful_time = startTime;
    INST->s.stop_time_defined = stopTimeDefined ? 1 : 0;
    INST->s.stop_time = stopTimeDefined ? stopTime : 0.0;
    /* the importer's tolerance is the CS relative tolerance unless rtol was
     * set explicitly */
    if (toleranceDefined && !INST->s.rtol_set) INST->s.rt[FMUGEN_RT_RTOL] = tolerance;
    INST->s.fsal_valid = 0;
    fmugen_invalidate(INST);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    CHECK_STATE(FMUGEN_INSTANTIATED, "fmi2EnterInitializationMode");
    INST->s.fmi_state = FMUGEN_INITIALIZATION_MODE;
    fmugen_log(INST, fmi2OK, FMUGEN_LOG_EVENTS, "fmi2EnterInitializationMode at t = %g", INST->s.time);
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    CHECK_STATE(FMUGEN_INITIALIZATION_MODE, "fmi2ExitInitializationMode");
    /* evaluate once: parameters that make the model fail (e.g. a mass matrix
     * that is not positive definite) are reported here, not in the middle
     * of a simulation */
    if (fmugen_evaluate_cached(INST, "fmi2ExitInitializationMode") != FMUGEN_OK) return fmi2Error;
    if (INST->model->ns) { /* the clocks' periods, checked once: a non-positive one is refused here */
        double next;
        int at;
        if (fmugen_next_tick(INST, INST->s.time, &next, &at) != FMUGEN_OK) {
            fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2ExitInitializationMode: a clock's sample period is not positive and finite");
            return fmi2Error;
        }
    }
    if (fmugen_has_events(INST->model) && INST->type == fmi2CoSimulation) {
        /* the initial event iteration (a stuck joint whose torque already exceeds breakaway starts
         * sliding; a clock whose first tick is the start samples); Model Exchange leaves it to the
         * importer's fmi2NewDiscreteStates in event mode */
        char msg[512];
        if (fmugen_tick_iteration(INST, INST->u, msg, sizeof msg) != FMUGEN_OK) {
            fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2ExitInitializationMode: %s", msg);
            return fmi2Error;
        }
        if (fmugen_evaluate_cached(INST, "fmi2ExitInitializationMode") != FMUGEN_OK) return fmi2Error;
    }
    INST->s.fmi_state = INST->type == fmi2ModelExchange ? FMUGEN_EVENT_MODE : FMUGEN_STEP_COMPLETE;
    INST->s.last_successful_time = INST->s.time;
    INST->s.h_next = 0.0;
    INST->s.fsal_valid = 0;
    fmugen_log(INST, fmi2OK, FMUGEN_LOG_EVENTS, "fmi2ExitInitializationMode: now in %s",
               fmugen_state_name(INST->s.fmi_state));
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    CHECK_STATE(FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | FMUGEN_STEP_COMPLETE | FMUGEN_STEP_FAILED,
                "fmi2Terminate");
    INST->s.fmi_state = FMUGEN_TERMINATED;
    fmugen_log(INST, fmi2OK, FMUGEN_LOG_EVENTS, "fmi2Terminate at t = %g", INST->s.time);
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    CHECK_STATE(ANY_STATE, "fmi2Reset");
    fmugen_set_defaults(INST);
    fmugen_log(INST, fmi2OK, FMUGEN_LOG_EVENTS, "fmi2Reset");
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* getting and setting variables                                             */
/* ------------------------------------------------------------------------ */

static int null_args(fmugen_instance *inst, const char *fn, size_t nvr, const void *vr, const void *value)
{
    if (nvr > 0 && (!vr || !value)) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: %s is NULL with nvr = %zu", fn,
                   !vr ? "vr[]" : "value[]", nvr);
        return 1;
    }
    return 0;
}

/* Status for a failed model evaluation: fmi2Discard in ME after
 * initialisation (the integrator may retry with a smaller step), else
 * fmi2Error. */
static fmi2Status eval_failure_status(const fmugen_instance *inst)
{
    return (inst->type == fmi2ModelExchange &&
            (inst->s.fmi_state & (FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE)))
               ? fmi2Discard
               : fmi2Error;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    CHECK_STATE(MASK_GET, "fmi2GetReal");
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    if (null_args(inst, "fmi2GetReal", nvr, vr, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= fmugen_vr_end(m)) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2GetReal: unknown value reference %u (Real variables are 0..%u)", vr[i],
                       fmugen_vr_end(m) - 1);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++) {
        const fmi2ValueReference r = vr[i];
        if (r < fmugen_vr_der(m)) value[i] = inst->x[r];
        else if (r < fmugen_vr_u(m) || (r >= fmugen_vr_y(m) && r < fmugen_vr_p(m))) {
            if (fmugen_evaluate_cached(inst, "fmi2GetReal") != FMUGEN_OK) return eval_failure_status(inst);
            value[i] = r < fmugen_vr_u(m) ? inst->dx_cache[r - fmugen_vr_der(m)] : inst->y_cache[r - fmugen_vr_y(m)];
        } else if (r < fmugen_vr_y(m)) value[i] = inst->u[r - fmugen_vr_u(m)];
        else if (r < fmugen_vr_rt(m)) value[i] = inst->p[r - fmugen_vr_p(m)];
        else if (r < fmugen_vr_d(m)) value[i] = inst->s.rt[r - fmugen_vr_rt(m)];
        else if (r < fmugen_vr_event_time(m)) value[i] = inst->p[m->np + (r - fmugen_vr_d(m))];
        else value[i] = inst->s.n_events ? inst->s.last_event_time : inst->s.start_time;
    }
    return fmi2OK;
}

/* Why value reference r may not be set now, or NULL when it may. */
static const char *set_real_refusal(const fmugen_instance *inst, fmi2ValueReference r)
{
    const fmugen_model_def *m = inst->model;
    const int before_end = (inst->s.fmi_state & MASK_BEFORE_INIT_END) != 0;
    if (r >= fmugen_vr_end(m)) return "unknown value reference";
    if (r < fmugen_vr_der(m))
        return before_end ? NULL
                          : (inst->type == fmi2ModelExchange
                                 ? "a state can be set only before fmi2ExitInitializationMode (afterwards use "
                                   "fmi2SetContinuousStates)"
                                 : "a state can be set only before fmi2ExitInitializationMode");
    if (r < fmugen_vr_u(m)) return "a derivative is computed by the model and cannot be set";
    if (r < fmugen_vr_y(m)) return NULL; /* input */
    if (r < fmugen_vr_p(m)) return "an output is computed by the model and cannot be set";
    if (r >= fmugen_vr_event_time(m)) return "the time of the last event is the runtime's and cannot be set";
    if (r >= fmugen_vr_d(m))
        return before_end ? NULL : "a discrete state changes only at events; its start can be set only before "
                                   "fmi2ExitInitializationMode";
    return before_end ? NULL : "a parameter (variability fixed) can be set only before fmi2ExitInitializationMode";
}

/* Range check of a runtime Real parameter; NULL when v is acceptable. */
static const char *rt_refusal(int k, double v)
{
    switch (k) {
    case FMUGEN_RT_RTOL: return (v > 0 && v < 1) ? NULL : "rtol must lie in (0, 1)";
    case FMUGEN_RT_ATOL: return v > 0 ? NULL : "atol must be positive";
    case FMUGEN_RT_MAX_STEP: return v >= 0 ? NULL : "max_step must be >= 0 (0 = no limit)";
    case FMUGEN_RT_FIXED_STEP: return v >= 0 ? NULL : "fixed_step must be >= 0 (0 = one step per communication step)";
    default: return "unknown runtime parameter";
    }
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    CHECK_STATE(MASK_SET_REAL, "fmi2SetReal");
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    if (null_args(inst, "fmi2SetReal", nvr, vr, value)) return fmi2Error;
    char name[256];
    /* check everything first: a refused call changes nothing */
    for (size_t i = 0; i < nvr; i++) {
        const char *why = set_real_refusal(inst, vr[i]);
        if (why) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2SetReal: cannot set %s (value reference %u) in state %s: %s",
                       fmugen_real_name(inst, vr[i], name, sizeof name), vr[i],
                       fmugen_state_name(inst->s.fmi_state), why);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2SetReal: value %g for %s (value reference %u) is not finite; rejected", value[i],
                       fmugen_real_name(inst, vr[i], name, sizeof name), vr[i]);
            return fmi2Error;
        }
        if (vr[i] >= fmugen_vr_p(m) && vr[i] < fmugen_vr_rt(m)) {
            /* the parameter's physical range (a mass > 0, a damping >= 0),
             * the min/max that modelDescription.xml declares */
            const int k = (int)(vr[i] - fmugen_vr_p(m));
            const double lo = m->p_min ? m->p_min[k] : -HUGE_VAL, hi = m->p_max ? m->p_max[k] : HUGE_VAL;
            if (value[i] < lo || value[i] > hi) {
                fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                           "fmi2SetReal: value %.17g for parameter %s (value reference %u) rejected: outside its "
                           "physical range [%.17g, %.17g] (min/max in modelDescription.xml); nothing was set",
                           value[i], fmugen_real_name(inst, vr[i], name, sizeof name), vr[i], lo, hi);
                return fmi2Error;
            }
        }
        if (vr[i] >= fmugen_vr_rt(m) && vr[i] < fmugen_vr_d(m)) {
            const char *bad = rt_refusal((int)(vr[i] - fmugen_vr_rt(m)), value[i]);
            if (bad) {
                fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                           "fmi2SetReal: value %g for %s (value reference %u) rejected: %s", value[i],
                           fmugen_real_name(inst, vr[i], name, sizeof name), vr[i], bad);
                return fmi2Error;
            }
        }
    }
    for (size_t i = 0; i < nvr; i++) {
        const fmi2ValueReference r = vr[i];
        double *slot;
        if (r < fmugen_vr_der(m)) slot = &inst->x[r];
        else if (r < fmugen_vr_y(m)) slot = &inst->u[r - fmugen_vr_u(m)];
        else if (r < fmugen_vr_rt(m)) slot = &inst->p[r - fmugen_vr_p(m)];
        else if (r >= fmugen_vr_d(m)) slot = &inst->p[m->np + (r - fmugen_vr_d(m))];
        else {
            slot = &inst->s.rt[r - fmugen_vr_rt(m)];
            if (r - fmugen_vr_rt(m) == FMUGEN_RT_RTOL) inst->s.rtol_set = 1;
        }
        /* the same value again keeps cached results (importers set every
         * input at every step) */
        if (*slot != value[i] || signbit(*slot) != signbit(value[i])) {
            *slot = value[i];
            if (r < fmugen_vr_rt(m) || r >= fmugen_vr_d(m)) {
                fmugen_invalidate(inst);
                inst->s.fsal_valid = 0;
            }
        }
    }
    return fmi2OK;
}

static const char *const int_names[FMUGEN_INT_COUNT] = {"solver", "n_steps", "n_rejected", "n_rhs", "n_jac",
                                                         "stiffness_detected", "range_check", "n_events"};

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    CHECK_STATE(MASK_GET, "fmi2GetInteger");
    fmugen_instance *inst = INST;
    if (null_args(inst, "fmi2GetInteger", nvr, vr, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= FMUGEN_INT_COUNT) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2GetInteger: unknown value reference %u (Integer variables are 0..%d)", vr[i],
                       FMUGEN_INT_COUNT - 1);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++) {
        long long v;
        switch (vr[i]) {
        case FMUGEN_INT_SOLVER: v = inst->s.solver; break;
        case FMUGEN_INT_N_STEPS: v = inst->s.n_steps; break;
        case FMUGEN_INT_N_REJECTED: v = inst->s.n_rejected; break;
        case FMUGEN_INT_N_RHS: v = inst->s.n_rhs; break;
        case FMUGEN_INT_N_JAC: v = inst->s.n_jac; break;
        case FMUGEN_INT_RANGE_CHECK: v = inst->s.range_check; break;
        case FMUGEN_INT_N_EVENTS: v = inst->s.n_events; break;
        default: v = inst->s.n_stiff; break;
        }
        value[i] = v > 2147483647LL ? 2147483647 : (fmi2Integer)v; /* counters saturate */
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    CHECK_STATE(MASK_SET_OTHER, "fmi2SetInteger");
    fmugen_instance *inst = INST;
    if (null_args(inst, "fmi2SetInteger", nvr, vr, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= FMUGEN_INT_COUNT) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2SetInteger: unknown value reference %u (Integer variables are 0..%d)", vr[i],
                       FMUGEN_INT_COUNT - 1);
            return fmi2Error;
        }
        if (vr[i] != FMUGEN_INT_SOLVER && vr[i] != FMUGEN_INT_RANGE_CHECK) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2SetInteger: cannot set %s (value reference %u): it is a solver counter (output of "
                       "the runtime)", int_names[vr[i]], vr[i]);
            return fmi2Error;
        }
        if (!(inst->s.fmi_state & MASK_BEFORE_INIT_END)) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2SetInteger: cannot set %s (value reference %u) in state %s: a parameter "
                       "(variability fixed) can be set only before fmi2ExitInitializationMode",
                       int_names[vr[i]], vr[i], fmugen_state_name(inst->s.fmi_state));
            return fmi2Error;
        }
        if (vr[i] == FMUGEN_INT_RANGE_CHECK) {
            if (value[i] < FMUGEN_RANGE_IGNORE || value[i] > FMUGEN_RANGE_ERROR) {
                fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                           "fmi2SetInteger: range_check = %d rejected: use 0 (ignore), 1 (warn) or 2 (error: "
                           "fmi2Discard)", value[i]);
                return fmi2Error;
            }
            continue;
        }
        if (value[i] < FMUGEN_SOLVER_DOPRI5 || value[i] > FMUGEN_SOLVER_RK4) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2SetInteger: solver = %d rejected: use 1 (Dormand-Prince 5(4)), 2 (implicit RODAS3) "
                       "or 3 (RK4, fixed step)", value[i]);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] == FMUGEN_INT_RANGE_CHECK) inst->s.range_check = value[i];
        else inst->s.solver = value[i];
    }
    return fmi2OK;
}

/* The runtime has no Boolean or String variables: any value reference is
 * unknown. */
static fmi2Status no_such_variables(fmugen_instance *inst, const char *fn, size_t nvr, const fmi2ValueReference vr[],
                                    const void *value)
{
    if (null_args(inst, fn, nvr, vr, value)) return fmi2Error;
    if (nvr > 0) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: unknown value reference %u (this FMU has no variables of that type)", fn, vr[0]);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    CHECK_STATE(MASK_GET, "fmi2GetBoolean");
    return no_such_variables(INST, "fmi2GetBoolean", nvr, vr, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    CHECK_STATE(MASK_GET, "fmi2GetString");
    return no_such_variables(INST, "fmi2GetString", nvr, vr, value);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    CHECK_STATE(MASK_SET_OTHER, "fmi2SetBoolean");
    return no_such_variables(INST, "fmi2SetBoolean", nvr, vr, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    CHECK_STATE(MASK_SET_OTHER, "fmi2SetString");
    return no_such_variables(INST, "fmi2SetString", nvr, vr, value);
}

/* ------------------------------------------------------------------------ */
/* directional derivatives                                                   */
/* ------------------------------------------------------------------------ */

/*
 * dv_unknown = (d unknown / d known) dv_known at the current point, from the
 * model's exact Jacobian:
 *   unknowns: derivatives der(x) (rows of dfdx, dfdu), computed outputs y
 *             (rows of dgdx, dgdu) and states (identity w.r.t. states, zero
 *             w.r.t. inputs: a state used as an output);
 *   knowns:   states x and inputs u.
 */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    CHECK_STATE(MASK_GET, "fmi2GetDirectionalDerivative");
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    const char *fn = "fmi2GetDirectionalDerivative";
    if ((nUnknown > 0 && (!vUnknown_ref || !dvUnknown)) || (nKnown > 0 && (!vKnown_ref || !dvKnown))) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: NULL array with a non-zero length", fn);
        return fmi2Error;
    }
    if (!m->has_jacobian || !m->jacobian) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: this model was generated without its Jacobian (providesDirectionalDerivative=false)", fn);
        return fmi2Error;
    }
    char name[256];
    for (size_t i = 0; i < nUnknown; i++) {
        fmi2ValueReference r = vUnknown_ref[i];
        int ok = r < fmugen_vr_u(m) || (r >= fmugen_vr_y(m) && r < fmugen_vr_p(m));
        if (!ok) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: %s (value reference %u) is not an unknown (a state, derivative or output)", fn,
                       r < fmugen_vr_end(m) ? fmugen_real_name(inst, r, name, sizeof name) : "<unknown>", r);
            return fmi2Error;
        }
    }
    for (size_t j = 0; j < nKnown; j++) {
        fmi2ValueReference r = vKnown_ref[j];
        int ok = r < fmugen_vr_der(m) || (r >= fmugen_vr_u(m) && r < fmugen_vr_y(m));
        if (!ok || !isfinite(dvKnown[j])) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: %s (value reference %u) is not a known (a state or input) or its seed is not finite",
                       fn, r < fmugen_vr_end(m) ? fmugen_real_name(inst, r, name, sizeof name) : "<unknown>", r);
            return fmi2Error;
        }
    }
    const int nx = m->nx, nu = m->nu, ny = m->ny;
    /* Jacobian blocks in the solver workspace: dfdx, dfdu, dgdx, dgdu */
    size_t need = (size_t)nx * nx + (size_t)nx * nu + (size_t)ny * nx + (size_t)ny * nu + 1;
    double *J = inst->cb.allocateMemory ? inst->cb.allocateMemory(need, sizeof(double)) : calloc(need, sizeof(double));
    if (!J) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: out of memory", fn);
        return fmi2Error;
    }
    double *dfdx = J, *dfdu = dfdx + nx * nx, *dgdx = dfdu + nx * nu, *dgdu = dgdx + ny * nx;
    int rc = m->jacobian(inst->p, inst->s.time, inst->x, inst->u, dfdx, dfdu, dgdx, dgdu);
    if (rc == FMUGEN_OK && !fmugen_all_finite(J, (int)(need - 1))) rc = FMUGEN_NOT_FINITE;
    fmi2Status status = fmi2OK;
    if (rc != FMUGEN_OK) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: Jacobian evaluation failed at t = %.17g: %s", fn,
                   inst->s.time, fmugen_model_status_text(rc));
        status = eval_failure_status(inst);
    } else {
        for (size_t i = 0; i < nUnknown; i++) {
            const fmi2ValueReference ru = vUnknown_ref[i];
            double s = 0.0;
            for (size_t j = 0; j < nKnown; j++) {
                const fmi2ValueReference rk = vKnown_ref[j];
                const int is_state = rk < fmugen_vr_der(m);
                const int col = is_state ? (int)rk : (int)(rk - fmugen_vr_u(m));
                double d;
                if (ru < fmugen_vr_der(m)) d = (is_state && (int)ru == col) ? 1.0 : 0.0;
                else if (ru < fmugen_vr_u(m)) {
                    int row = (int)(ru - fmugen_vr_der(m));
                    d = is_state ? dfdx[row * nx + col] : dfdu[row * nu + col];
                } else {
                    int row = (int)(ru - fmugen_vr_y(m));
                    d = is_state ? dgdx[row * nx + col] : dgdu[row * nu + col];
                }
                s += d * dvKnown[j];
            }
            dvUnknown[i] = s;
        }
    }
    if (inst->cb.freeMemory) inst->cb.freeMemory(J);
    else free(J);
    return status;
}
