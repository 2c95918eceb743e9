/* fmi2_model_exchange.c -- the FMI 2.0 Model Exchange functions.  The
 * importer integrates dx/dt = f(t, x, u, p, d), watches the event
 * indicators (fmi2GetEventIndicators) and, at an event, calls
 * fmi2NewDiscreteStates until it says the iteration is over: each call is
 * one round of the model's clauses (events.c).  A smooth model has no
 * indicators, and its event mode only passes through.  The states allowed
 * for each function are listed in fmi2_functions.c. */
#include <math.h>
#include <string.h>
#include "fmugen_runtime.h"
#include "solver.h"

#define INST ((fmugen_instance *)c)
#define ME_CHECK(mask, fn)                                   \
    if (!fmugen_live(INST) || !is_me(INST, (fn))) return fmi2Error;       \
    if (!fmugen_check_state(INST, (mask), (fn))) return fmi2Error

static int is_me(fmugen_instance *inst, const char *fn)
{
    if (inst->type == fmi2ModelExchange) return 1;
    fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
               "%s: a Model Exchange function called on a Co-Simulation instance", fn);
    return 0;
}

static int bad_length(fmugen_instance *inst, const char *fn, const char *what, size_t n, int expected,
                      const void *array)
{
    if (n != (size_t)expected) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: %s = %zu, but the model has %d", fn, what, n,
                   expected);
        return 1;
    }
    if (n > 0 && !array) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: the array is NULL with %s = %zu", fn, what, n);
        return 1;
    }
    return 0;
}

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    ME_CHECK(FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE, "fmi2EnterEventMode");
    INST->s.fmi_state = FMUGEN_EVENT_MODE;
    INST->s.last_successful_time = INST->s.time; /* time may not go back before an event */
    INST->s.event_rounds = 0;
    INST->s.x_reinit = 0;
    fmugen_log(INST, fmi2OK, FMUGEN_LOG_EVENTS, "fmi2EnterEventMode at t = %g", INST->s.time);
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo)
{
    ME_CHECK(FMUGEN_EVENT_MODE, "fmi2NewDiscreteStates");
    if (!eventInfo) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2NewDiscreteStates: eventInfo is NULL");
        return fmi2Error;
    }
    fmugen_instance *inst = INST;
    int changed = 0, x_changed = 0;
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False; /* set below when the model has clocks */
    eventInfo->nextEventTime = 0.0;
    if (fmugen_has_events(inst->model)) {
        /* one round of the clauses; another is needed while a round changes something */
        if (++inst->s.event_rounds > FMUGEN_EVENT_MAX_ROUNDS) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2NewDiscreteStates: the event iteration at t = %.17g does not converge: the clauses still "
                       "change a discrete state or a state after %d rounds", inst->s.time, FMUGEN_EVENT_MAX_ROUNDS);
            return fmi2Error;
        }
        int rc = fmugen_tick_round(inst, inst->u, &changed, &x_changed);
        if (rc != FMUGEN_OK) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2NewDiscreteStates: the event update at t = %.17g failed: %s", inst->s.time,
                       fmugen_model_status_text(rc));
            return fmi2Error;
        }
        if (x_changed) inst->s.x_reinit = 1;
        if (inst->s.event_rounds == 1) inst->s.n_events++;
        eventInfo->newDiscreteStatesNeeded = changed ? fmi2True : fmi2False;
        /* sticky over the iteration: an importer that reads only the last round's flag still
         * fetches the re-initialised states */
        eventInfo->valuesOfContinuousStatesChanged = inst->s.x_reinit ? fmi2True : fmi2False;
        if (changed)
            fmugen_log(inst, fmi2OK, FMUGEN_LOG_EVENTS, "fmi2NewDiscreteStates at t = %.17g: round %d changed %s",
                       inst->s.time, inst->s.event_rounds, x_changed ? "states" : "discrete states");
        if (inst->model->ns) { /* the next sample instant: a time event */
            double next;
            int at;
            if (fmugen_next_tick(inst, inst->s.time, &next, &at) == FMUGEN_OK && isfinite(next)) {
                eventInfo->nextEventTimeDefined = fmi2True;
                eventInfo->nextEventTime = next;
            }
        }
    }
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    ME_CHECK(FMUGEN_EVENT_MODE, "fmi2EnterContinuousTimeMode");
    INST->s.fmi_state = FMUGEN_CONTINUOUS_TIME_MODE;
    INST->s.event_rounds = 0;
    INST->s.x_reinit = 0;
    INST->s.last_successful_time = INST->s.time;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    ME_CHECK(FMUGEN_CONTINUOUS_TIME_MODE, "fmi2CompletedIntegratorStep");
    if (!enterEventMode || !terminateSimulation) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2CompletedIntegratorStep: enterEventMode or terminateSimulation is NULL");
        return fmi2Error;
    }
    if (noSetFMUStatePriorToCurrentPoint != fmi2True && noSetFMUStatePriorToCurrentPoint != fmi2False) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2CompletedIntegratorStep: noSetFMUStatePriorToCurrentPoint = %d is not a Boolean "
                   "(fmi2True = 1 or fmi2False = 0)", (int)noSetFMUStatePriorToCurrentPoint);
        return fmi2Error;
    }
    /* the step is accepted: the integrator will not go back before it */
    INST->s.last_successful_time = INST->s.time;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    /* validity ranges at the accepted point (the Model Exchange counterpart
     * of the check after fmi2DoStep); range_check = 2 ends the simulation */
    if (fmugen_range_action(INST) != FMUGEN_RANGE_IGNORE && fmugen_has_ranges(INST->model)) {
        if (fmugen_evaluate_cached(INST, "fmi2CompletedIntegratorStep") != FMUGEN_OK) return fmi2Error;
        char msg[512] = "";
        fmi2Status st = fmugen_check_ranges(INST, "fmi2CompletedIntegratorStep", msg, sizeof msg);
        if (st == fmi2Discard) {
            *terminateSimulation = fmi2True;
            fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2CompletedIntegratorStep: %s (range_check = 2: "
                       "the simulation must end)", msg);
            return fmi2Error;
        }
        return st;
    }
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    ME_CHECK(FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE, "fmi2SetTime");
    if (!isfinite(time)) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "fmi2SetTime: time %g is not finite", time);
        return fmi2Error;
    }
    /* an integrator may try any time after the last accepted point (a
     * rejected step goes back to it), never before it */
    if (time < INST->s.last_successful_time) {
        fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2SetTime: time %.17g goes back before t = %.17g (the last completed integrator step, "
                   "event or initialisation); restore an FMU state to go back", time,
                   INST->s.last_successful_time);
        return fmi2Error;
    }
    if (time != INST->s.time) {
        INST->s.time = time;
        fmugen_invalidate(INST);
    }
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    ME_CHECK(FMUGEN_CONTINUOUS_TIME_MODE, "fmi2SetContinuousStates");
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    if (bad_length(inst, "fmi2SetContinuousStates", "nx", nx, m->nx, x)) return fmi2Error;
    for (int i = 0; i < m->nx; i++) {
        if (!isfinite(x[i])) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2SetContinuousStates: value %g for state %s (x[%d]) is not finite; rejected", x[i],
                       m->x_names[i], i);
            return fmi2Error;
        }
    }
    if (m->nx && memcmp(inst->x, x, (size_t)m->nx * sizeof(double)) != 0) {
        memcpy(inst->x, x, (size_t)m->nx * sizeof(double));
        fmugen_invalidate(inst);
    }
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    ME_CHECK(FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | FMUGEN_TERMINATED | FMUGEN_ERROR,
             "fmi2GetDerivatives");
    fmugen_instance *inst = INST;
    if (bad_length(inst, "fmi2GetDerivatives", "nx", nx, inst->model->nx, derivatives)) return fmi2Error;
    if (fmugen_evaluate_cached(inst, "fmi2GetDerivatives") != FMUGEN_OK)
        /* the integrator may retry with a smaller step (FMI 2.0 sec. 2.1.3) */
        return (inst->s.fmi_state & (FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE)) ? fmi2Discard : fmi2Error;
    if (nx) memcpy(derivatives, inst->dx_cache, nx * sizeof(double));
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    ME_CHECK(FMUGEN_INITIALIZATION_MODE | FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | FMUGEN_TERMINATED |
                 FMUGEN_ERROR,
             "fmi2GetEventIndicators");
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    if (bad_length(inst, "fmi2GetEventIndicators", "ni", ni, m->nz, eventIndicators)) return fmi2Error;
    if (ni == 0) return fmi2OK;
    int rc = fmugen_event_indicators(inst, inst->s.time, inst->x, inst->u, eventIndicators);
    if (rc != FMUGEN_OK) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2GetEventIndicators: the indicators could not be evaluated at t = %.17g: %s", inst->s.time,
                   fmugen_model_status_text(rc));
        return (inst->s.fmi_state & (FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE)) ? fmi2Discard : fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    ME_CHECK(FMUGEN_INITIALIZATION_MODE | FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | FMUGEN_TERMINATED |
                 FMUGEN_ERROR,
             "fmi2GetContinuousStates");
    fmugen_instance *inst = INST;
    if (bad_length(inst, "fmi2GetContinuousStates", "nx", nx, inst->model->nx, x)) return fmi2Error;
    if (nx) memcpy(x, inst->x, nx * sizeof(double));
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    ME_CHECK(FMUGEN_INSTANTIATED | FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | FMUGEN_TERMINATED |
                 FMUGEN_ERROR,
             "fmi2GetNominalsOfContinuousStates");
    fmugen_instance *inst = INST;
    if (bad_length(inst, "fmi2GetNominalsOfContinuousStates", "nx", nx, inst->model->nx, x_nominal))
        return fmi2Error;
    if (nx) memcpy(x_nominal, inst->model->x_nominal, nx * sizeof(double));
    return fmi2OK;
}
