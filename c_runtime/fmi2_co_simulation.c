/* fmi2_co_simulation.c -- the FMI 2.0 Co-Simulation functions: fmi2DoStep
 * runs the selected solver (solver_*.c) over one communication step, with
 * inputs held constant or extrapolated linearly from the derivatives given
 * by fmi2SetRealInputDerivatives.  The states allowed for each function are
 * listed in fmi2_functions.c. */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmugen_runtime.h"
#include "solver.h"

#define INST ((fmugen_instance *)c)
#define CS_CHECK(mask, fn)                                   \
    if (!fmugen_live(INST) || !is_cs(INST, (fn))) return fmi2Error;       \
    if (!fmugen_check_state(INST, (mask), (fn))) return fmi2Error
#define MASK_STATUS (FMUGEN_STEP_COMPLETE | FMUGEN_STEP_FAILED | FMUGEN_TERMINATED)

static int is_cs(fmugen_instance *inst, const char *fn)
{
    if (inst->type == fmi2CoSimulation) return 1;
    fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
               "%s: a Co-Simulation function called on a Model Exchange instance", fn);
    return 0;
}

/*
 * Input derivatives: orders 1 to 3 are stored and used to extrapolate the
 * input over the following communication steps, u(t) = u(t_c) + du (t - t_c)
 * + ddu (t - t_c)^2 / 2 + dddu (t - t_c)^3 / 6, until they are set again (0
 * switches a term off).  Three orders let a master pass a cubic Hermite
 * interpolant (values and slopes at both ends of the step).
 * FMI 2.0 has no flag telling the master the highest order a slave uses, so
 * higher orders are accepted and ignored with a warning.
 */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    CS_CHECK(FMUGEN_INSTANTIATED | FMUGEN_INITIALIZATION_MODE | FMUGEN_STEP_COMPLETE,
             "fmi2SetRealInputDerivatives");
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    const char *fn = "fmi2SetRealInputDerivatives";
    if (nvr > 0 && (!vr || !order || !value)) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: vr[], order[] or value[] is NULL with nvr = %zu",
                   fn, nvr);
        return fmi2Error;
    }
    char name[256];
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] < fmugen_vr_u(m) || vr[i] >= fmugen_vr_y(m)) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: %s (value reference %u) is not an input", fn,
                       vr[i] < fmugen_vr_end(m) ? fmugen_real_name(inst, vr[i], name, sizeof name) : "<unknown>",
                       vr[i]);
            return fmi2Error;
        }
        if (order[i] < 1) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: order %d for %s must be >= 1", fn, order[i],
                       fmugen_real_name(inst, vr[i], name, sizeof name));
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: derivative %g of %s (value reference %u) is not finite; rejected", fn, value[i],
                       fmugen_real_name(inst, vr[i], name, sizeof name), vr[i]);
            return fmi2Error;
        }
    }
    fmi2Status status = fmi2OK;
    for (size_t i = 0; i < nvr; i++) {
        if (order[i] == 1) {
            inst->du[vr[i] - fmugen_vr_u(m)] = value[i];
        } else if (order[i] == 2) {
            inst->ddu[vr[i] - fmugen_vr_u(m)] = value[i];
        } else if (order[i] == 3) {
            inst->dddu[vr[i] - fmugen_vr_u(m)] = value[i];
        } else {
            fmugen_log(inst, fmi2Warning, FMUGEN_LOG_STATUS_WARNING,
                       "%s: derivative of order %d of %s ignored (inputs are extrapolated to third order)", fn,
                       order[i],
                       fmugen_real_name(inst, vr[i], name, sizeof name));
            status = fmi2Warning;
        }
    }
    return status;
}

/*
 * First time derivatives of outputs (order 1 only):
 *   a state used as an output:  dx_i/dt = f_i(t, x, u, p);
 *   a computed output y_j:      dy/dt = dg/dx f + dg/du du + dg/dt,
 * with the model's exact Jacobian and a central difference for the explicit
 * time dependence dg/dt (exactly zero when g does not depend on t).  Needs
 * the Jacobian: without it the call fails.
 */
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    CS_CHECK(FMUGEN_STEP_COMPLETE | FMUGEN_STEP_FAILED | FMUGEN_TERMINATED | FMUGEN_ERROR,
             "fmi2GetRealOutputDerivatives");
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    const char *fn = "fmi2GetRealOutputDerivatives";
    if (nvr > 0 && (!vr || !order || !value)) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: vr[], order[] or value[] is NULL with nvr = %zu",
                   fn, nvr);
        return fmi2Error;
    }
    char name[256];
    int need_jac = 0;
    for (size_t i = 0; i < nvr; i++) {
        int is_state = vr[i] < fmugen_vr_der(m), is_y = vr[i] >= fmugen_vr_y(m) && vr[i] < fmugen_vr_p(m);
        if (!is_state && !is_y) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: %s (value reference %u) is not an output", fn,
                       vr[i] < fmugen_vr_end(m) ? fmugen_real_name(inst, vr[i], name, sizeof name) : "<unknown>",
                       vr[i]);
            return fmi2Error;
        }
        if (order[i] != 1) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "%s: order %d for %s not provided (maxOutputDerivativeOrder is 1)", fn, order[i],
                       fmugen_real_name(inst, vr[i], name, sizeof name));
            return fmi2Error;
        }
        if (is_y) need_jac = 1;
    }
    if (nvr == 0) return fmi2OK;
    if (need_jac && (!m->has_jacobian || !m->jacobian)) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: derivatives of computed outputs need the model's Jacobian, which was not generated", fn);
        return fmi2Error;
    }
    if (fmugen_evaluate_cached(inst, fn) != FMUGEN_OK) return fmi2Error;
    const int nx = m->nx, nu = m->nu, ny = m->ny;
    double *dydt = NULL;
    if (need_jac) {
        size_t need = (size_t)ny * nx + (size_t)ny * nu + 3 * (size_t)ny + 1;
        double *buf = inst->cb.allocateMemory ? inst->cb.allocateMemory(need, sizeof(double))
                                              : calloc(need, sizeof(double));
        if (!buf) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: out of memory", fn);
            return fmi2Error;
        }
        double *dgdx = buf, *dgdu = dgdx + ny * nx, *yp = dgdu + ny * nu, *ym = yp + ny;
        dydt = ym + ny;
        const double t = inst->s.time, dt = 1.4901161193847656e-08 * fmax(fabs(t), 1.0);
        int rc = m->jacobian(inst->p, t, inst->x, inst->u, NULL, NULL, dgdx, dgdu);
        if (rc == FMUGEN_OK) rc = m->evaluate(inst->p, t + dt, inst->x, inst->u, NULL, yp);
        if (rc == FMUGEN_OK) rc = m->evaluate(inst->p, t - dt, inst->x, inst->u, NULL, ym);
        if (rc == FMUGEN_OK) {
            for (int j = 0; j < ny; j++) {
                double s = (yp[j] - ym[j]) / (2 * dt);
                for (int k = 0; k < nx; k++) s += dgdx[j * nx + k] * inst->dx_cache[k];
                for (int k = 0; k < nu; k++) s += dgdu[j * nu + k] * inst->du[k];
                dydt[j] = s;
            }
            if (!fmugen_all_finite(dydt, ny)) rc = FMUGEN_NOT_FINITE;
        }
        if (rc != FMUGEN_OK) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: Jacobian evaluation failed at t = %.17g: %s",
                       fn, t, fmugen_model_status_text(rc));
            if (inst->cb.freeMemory) inst->cb.freeMemory(buf);
            else free(buf);
            return fmi2Error;
        }
        for (size_t i = 0; i < nvr; i++)
            if (vr[i] >= fmugen_vr_y(m)) value[i] = dydt[vr[i] - fmugen_vr_y(m)];
        if (inst->cb.freeMemory) inst->cb.freeMemory(buf);
        else free(buf);
    }
    for (size_t i = 0; i < nvr; i++)
        if (vr[i] < fmugen_vr_der(m)) value[i] = inst->dx_cache[vr[i]];
    return fmi2OK;
}

static const char *solver_name(int solver)
{
    switch (solver) {
    case FMUGEN_SOLVER_DOPRI5: return "Dormand-Prince 5(4)";
    case FMUGEN_SOLVER_IMPLICIT: return "RODAS3";
    default: return "RK4";
    }
}

/* Smallest number of significant digits of the step size H that must
 * survive the sum t + H: (t + H) - t differs from H by up to half an ulp of
 * t + H, so at t = 1e10 a step of 0.01 keeps only 4 digits, and at t = 1e15
 * none (t + H == t: time would not advance at all). */
#define FMUGEN_STEP_REL_RESOLUTION 1e-6

/* Back to the start of the communication step: states, inputs, input
 * derivatives, discrete states and indicator memory as fmi2DoStep found them
 * (inst->step_start), time tc. */
static void restore_step_start(fmugen_instance *inst, double tc)
{
    memcpy(inst->vec, inst->step_start, inst->n_vec * sizeof(double));
    inst->s.time = tc;
    inst->s.fsal_valid = 0;
    fmugen_invalidate(inst);
}

/* 1 when the point a failed solver stopped at is good: finite states whose
 * evaluation gives finite derivatives and outputs (cached for fmi2GetReal). */
static int kept_point_is_good(fmugen_instance *inst)
{
    const fmugen_model_def *m = inst->model;
    if (!fmugen_all_finite(inst->x, m->nx)) return 0;
    fmugen_invalidate(inst);
    int rc = m->evaluate(inst->p, inst->s.time, inst->x, inst->u, inst->dx_cache, inst->y_cache);
    if (rc == FMUGEN_OK && !(fmugen_all_finite(inst->dx_cache, m->nx) && fmugen_all_finite(inst->y_cache, m->ny)))
        rc = FMUGEN_NOT_FINITE;
    inst->cache_status = rc;
    inst->cache_valid = 1;
    return rc == FMUGEN_OK;
}

/* The event iteration at a state event the solver located (inst->s.time,
 * inst->x just after the crossing); an event storm -- FMUGEN_EVENT_STORM_RUN
 * events each within FMUGEN_EVENT_STORM_GAP of the one before, or
 * FMUGEN_EVENT_MAX_PER_STEP in one communication step -- fails the step
 * naming the indicator instead of running forever. */
/* Does a clock tick at t (within the tick tolerance)? */
static int tick_at(fmugen_instance *inst, double t)
{
    double next;
    int at = 0;
    return fmugen_next_tick(inst, t, &next, &at) == FMUGEN_OK && at;
}

/* The event iteration at the located state event at inst->s.time with the inputs u there; fn names the
 * FMI function in the log message (fmi2DoStep inside the step, fmi3UpdateDiscreteStates in FMI 3.0's
 * Event Mode, which must run exactly this iteration so that both give the same results). */
static int event_at(fmugen_instance *inst, const double *u, long long n_in_step, const char *fn, char *msg,
                    size_t n)
{
    const double te = inst->s.time;
    char zname[160];
    fmugen_indicator_name(inst, inst->s.last_indicator, zname, sizeof zname);
    if (inst->s.n_events > 0 && te - inst->s.last_event_time <= FMUGEN_EVENT_STORM_GAP * fmax(1.0, fabs(te)))
        inst->s.storm_run++;
    else
        inst->s.storm_run = 0;
    inst->s.n_events++;
    inst->s.last_event_time = te;
    if (inst->s.storm_run >= FMUGEN_EVENT_STORM_RUN || n_in_step > FMUGEN_EVENT_MAX_PER_STEP) {
        if (inst->s.storm_run >= FMUGEN_EVENT_STORM_RUN)
            snprintf(msg, n, "event storm at t = %.17g: %d events each within %.3g s of the one before (Zeno "
                     "behaviour or chattering: the model switches without time passing); the last on indicator %s",
                     te, inst->s.storm_run, FMUGEN_EVENT_STORM_GAP * fmax(1.0, fabs(te)), zname);
        else
            snprintf(msg, n, "event storm at t = %.17g: more than %d events in one communication step; the last on "
                     "indicator %s", te, FMUGEN_EVENT_MAX_PER_STEP, zname);
        return FMUGEN_SOLVER_FAILED;
    }
    char why[300];
    if (fmugen_event_iteration(inst, u, why, sizeof why) != FMUGEN_OK) {
        snprintf(msg, n, "at the event on indicator %.150s: %s", zname, why);
        return FMUGEN_SOLVER_FAILED;
    }
    fmugen_log(inst, fmi2OK, FMUGEN_LOG_EVENTS, "%s: state event at t = %.17g on indicator %s", fn, te, zname);
    return FMUGEN_SOLVER_OK;
}

static int handle_event(fmugen_instance *inst, fmugen_ode *ode, long long n_in_step, char *msg, size_t n)
{
    double *u = ode->u_work;
    fmugen_ode_inputs(ode, inst->s.time, u);
    return event_at(inst, u, n_in_step, "fmi2DoStep", msg, n);
}

int fmugen_cs_event_update(fmugen_instance *inst, const char *fn, int inputs_changed, char *msg, size_t n)
{
    const int pending = inst->s.cs_event_pending;
    inst->s.cs_event_pending = 0;
    /* fmi2DoStep left inst->u at the inputs of the event's time (the importer may have set others in
     * Event Mode since): what handle_event and the sample instant below compute inside the step */
    if (pending & FMUGEN_PENDING_STATE_EVENT) {
        /* one event per step: the step stopped at it (n_in_step counts the events of one step) */
        if (event_at(inst, inst->u, 1, fn, msg, n) != FMUGEN_SOLVER_OK) return FMUGEN_NOT_FINITE;
    }
    if (pending & FMUGEN_PENDING_TICK) {
        char why[300];
        if (fmugen_tick_iteration(inst, inst->u, why, sizeof why) != FMUGEN_OK) {
            snprintf(msg, n, "at the sample instant t = %.17g: %s", inst->s.time, why);
            return FMUGEN_NOT_FINITE;
        }
        inst->s.fsal_valid = 0;
    }
    if (!pending && inputs_changed && fmugen_has_events(inst->model)) {
        /* no event of the FMU's own, but inputs set in Event Mode: the clauses see them (a guard on an
         * input), as at any event */
        if (fmugen_event_iteration(inst, inst->u, msg, n) != FMUGEN_OK) return FMUGEN_NOT_FINITE;
    }
    return FMUGEN_OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    CS_CHECK(FMUGEN_STEP_COMPLETE, "fmi2DoStep");
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    const double tc = currentCommunicationPoint, H = communicationStepSize;
    const double t = inst->s.time;
    if (!isfinite(tc) || !isfinite(H) || !(H > 0)) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2DoStep: communication point %g and step size %g must be finite, the step size > 0", tc, H);
        return fmi2Error;
    }
    if (noSetFMUStatePriorToCurrentPoint != fmi2True && noSetFMUStatePriorToCurrentPoint != fmi2False) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2DoStep: noSetFMUStatePriorToCurrentPoint = %d is not a Boolean (fmi2True = 1 or "
                   "fmi2False = 0)", (int)noSetFMUStatePriorToCurrentPoint);
        return fmi2Error;
    }
    {
        const double advanced = (tc + H) - tc;
        /* after an early return (FMI 3.0) the rest of a communication step can be any sliver of it: it
         * needs only to advance time, and ends where the importer's tc + h rounds to */
        const int sliver_ok = inst->cs_ext && inst->cs_ext->early_return_allowed && advanced > 0;
        if (advanced == 0 || (fabs(advanced - H) > FMUGEN_STEP_REL_RESOLUTION * H && !sliver_ok)) {
            fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                       "fmi2DoStep: a step of %.17g s at t = %.17g cannot be resolved in double precision "
                       "(t + h - t = %.17g); time would %s. Start the experiment at a smaller time or take larger "
                       "steps", H, tc, advanced, advanced == 0 ? "not advance" : "advance by a wrong amount");
            return fmi2Error;
        }
    }
    /* importers compute communication points by their own arithmetic:
     * accept a difference of rounding size and take the importer's time */
    const double slack = 1e-9 * fmax(fmax(fabs(t), fabs(H)), 1e-3);
    if (fabs(tc - t) > slack) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2DoStep: currentCommunicationPoint %.17g is not the FMU's time %.17g", tc, t);
        return fmi2Error;
    }
    if (inst->s.stop_time_defined && tc + H > inst->s.stop_time + 1e-9 * fmax(fabs(inst->s.stop_time), 1.0)) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2DoStep: the step to %.17g goes past the stop time %.17g given to fmi2SetupExperiment",
                   tc + H, inst->s.stop_time);
        return fmi2Error;
    }
    if (tc != t) {
        inst->s.time = tc;
        inst->s.fsal_valid = 0;
        fmugen_invalidate(inst);
    }

    /* the last good point, should the end point fail its checks */
    memcpy(inst->step_start, inst->vec, inst->n_vec * sizeof(double));
    const size_t off = fmugen_solver_work_doubles(m->nx);
    double *u0 = inst->work + off, *u_work = u0 + m->nu;
    if (m->nu) memcpy(u0, inst->u, (size_t)m->nu * sizeof(double));
    fmugen_ode ode = {inst, tc, u0, u_work, FMUGEN_OK};
    const double t_end = tc + H;
    char msg[512] = "";
    const long long steps0 = inst->s.n_steps, rej0 = inst->s.n_rejected, rhs0 = inst->s.n_rhs;
    int rc;
    long long events = 0;
    /* FMI 3.0 (NULL for FMI 2.0): events left to the importer's Event Mode, early returns */
    fmugen_cs_ext *const ext = inst->cs_ext;
    const int to_event_mode = ext && ext->event_mode_used;
    if (ext) {
        ext->step_end = t_end;
        ext->stop_at = HUGE_VAL;
        ext->returned_early = 0;
    }
    for (;;) {
        /* a sampled component's next tick inside the step is a time event: integrate exactly to it */
        double target = t_end, tick = HUGE_VAL;
        int at;
        /* a tick within the tolerance of the step's end is the end's (no step of a rounding error) */
        if (m->ns && fmugen_next_tick(inst, inst->s.time, &tick, &at) == FMUGEN_OK &&
            t_end - tick > 1e-9 * H + 8 * DBL_EPSILON * fabs(t_end))
            target = tick;
        int to_tick = target < t_end || (m->ns && tick_at(inst, t_end));
        if (ext) {
            if (ext->stop_at < target) { /* the importer's earlyReturnTime comes first */
                target = ext->stop_at;
                to_tick = 0;
            }
            ext->target = target;
        }
        switch (inst->s.solver) {
        case FMUGEN_SOLVER_IMPLICIT: rc = fmugen_solve_rodas3(&ode, target, msg, sizeof msg); break;
        case FMUGEN_SOLVER_RK4: rc = fmugen_solve_rk4(&ode, target, msg, sizeof msg); break;
        default: rc = fmugen_solve_dopri5(&ode, target, msg, sizeof msg); break;
        }
        if (rc == FMUGEN_SOLVER_EARLY) {
            /* the importer asked for an early return in the intermediate update: at this step's end, or
             * on to the later earlyReturnTime it gave */
            rc = FMUGEN_SOLVER_OK;
            if (ext->stop_at > inst->s.time) continue;
            break;
        }
        if (rc == FMUGEN_SOLVER_EVENT) {
            if (to_event_mode && ext->early_return_allowed) {
                /* the step ends at the event, the state just after the crossing: the importer's Event
                 * Mode runs its iteration (fmugen_cs_event_update) */
                inst->s.cs_event_pending |= FMUGEN_PENDING_STATE_EVENT;
                rc = FMUGEN_SOLVER_OK;
                break;
            }
            /* a state event located inside the step: the event iteration at its
             * time with the inputs there, then on to the communication point */
            rc = handle_event(inst, &ode, ++events, msg, sizeof msg);
            if (rc != FMUGEN_SOLVER_OK) break;
            if (ext && ext->early_return_allowed) break; /* a communication point at the discontinuity */
            continue;
        }
        if (rc != FMUGEN_SOLVER_OK) break;
        if (to_tick && to_event_mode && (ext->early_return_allowed || target >= t_end)) {
            /* the sample instant is the importer's event (eventHandlingNeeded): ended here, the clocks'
             * iteration left to its Event Mode */
            inst->s.time = target;
            inst->s.cs_event_pending |= FMUGEN_PENDING_TICK;
            break;
        }
        if (to_tick) { /* the sample instant: the clocks' event iteration, with the inputs there */
            inst->s.time = target;
            fmugen_ode_inputs(&ode, target, u_work);
            char why[300];
            if (fmugen_tick_iteration(inst, u_work, why, sizeof why) != FMUGEN_OK) {
                snprintf(msg, sizeof msg, "at the sample instant t = %.17g: %s", target, why);
                rc = FMUGEN_SOLVER_FAILED;
                break;
            }
            /* not counted in n_events: a sample instant is a time event a master knows beforehand (the
             * clocks are in the description), not a discontinuity it has to find */
            inst->s.fsal_valid = 0;
            if (ext && ext->early_return_allowed && target < t_end) break; /* a communication point there */
        }
        if (target >= t_end) break;
        if (ext && inst->s.time >= ext->stop_at) break; /* the importer's earlyReturnTime reached */
    }
    /* FMI 3.0: the step ended before tc + h (an event, the importer's request); never for FMI 2.0 */
    const int early = ext && rc == FMUGEN_SOLVER_OK && inst->s.time < t_end;
    /* inputs at the time reached, so that outputs and the next step see a
     * continuous input */
    fmugen_ode_inputs(&ode, inst->s.time, inst->u);
    /* the polynomial goes on from the new point: its slope there */
    const double s_end = inst->s.time - tc;
    for (int i = 0; i < m->nu; i++) {
        if (inst->dddu[i] != 0.0) {
            inst->du[i] += (inst->ddu[i] + 0.5 * inst->dddu[i] * s_end) * s_end;
            inst->ddu[i] += inst->dddu[i] * s_end;
        } else if (inst->ddu[i] != 0.0) {
            inst->du[i] += inst->ddu[i] * s_end;
        }
    }
    fmugen_invalidate(inst);
    if (rc != FMUGEN_SOLVER_OK) {
        /* the solvers move x and time only on accepted internal steps; a
         * point that does not evaluate cleanly is no good point either */
        if (inst->s.time != tc && !kept_point_is_good(inst)) restore_step_start(inst, tc);
        inst->s.last_successful_time = inst->s.time;
        inst->s.fmi_state = FMUGEN_STEP_FAILED;
        inst->s.last_do_step_status = fmi2Discard;
        inst->s.fsal_valid = 0;
        fmugen_log(inst, fmi2Discard, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2DoStep from t = %.17g to %.17g discarded: %s; the state is kept at the last good point "
                   "t = %.17g (fmi2GetRealStatus(fmi2LastSuccessfulTime))",
                   tc, t_end, msg, inst->s.time);
        return fmi2Discard;
    }
    if (!early) inst->s.time = t_end;
    const double t_reached = inst->s.time;
    /* never fmi2OK about an unchecked point: states, and outputs and
     * derivatives at the end point, finite; values inside their validity ranges */
    fmi2Status checked = fmugen_check_step_result(inst, "fmi2DoStep", msg, sizeof msg);
    if (checked == fmi2Discard) {
        /* the state goes back to where the step started, so that fmi2GetReal
         * gives what the message and fmi2LastSuccessfulTime say */
        restore_step_start(inst, tc);
        inst->s.cs_event_pending = 0; /* the event it stopped at is undone with it */
        inst->s.fmi_state = FMUGEN_STEP_FAILED;
        inst->s.last_do_step_status = fmi2Discard;
        inst->s.last_successful_time = tc;
        fmugen_log(inst, fmi2Discard, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2DoStep from t = %.17g to %.17g discarded: %s; the state is kept at the last good point "
                   "t = %.17g (fmi2GetRealStatus(fmi2LastSuccessfulTime))", tc, t_end, msg, tc);
        return fmi2Discard;
    }
    inst->s.last_successful_time = t_reached;
    inst->s.last_do_step_status = checked;
    if (ext) ext->returned_early = early;
    fmugen_log(inst, fmi2OK, FMUGEN_LOG_ALL, "fmi2DoStep to t = %.17g with %s: %lld steps, %lld rejected, %lld f%s",
               t_reached, solver_name(inst->s.solver), inst->s.n_steps - steps0, inst->s.n_rejected - rej0,
               inst->s.n_rhs - rhs0, early ? " (returned early)" : "");
    return checked;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    /* fmi2DoStep is synchronous (never fmi2Pending): there is never a step in
     * progress to cancel */
    if (!fmugen_live(INST)) return fmi2Error;
    fmugen_log(INST, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
               "fmi2CancelStep: not allowed in state %s (no asynchronous step in progress)",
               fmugen_state_name(INST->s.fmi_state));
    return fmi2Error;
}

static fmi2Status bad_status_kind(fmugen_instance *inst, const char *fn, fmi2StatusKind s)
{
    fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: status kind %d not provided by this function", fn,
               (int)s);
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    CS_CHECK(MASK_STATUS, "fmi2GetStatus");
    if (!value) return bad_status_kind(INST, "fmi2GetStatus (value is NULL)", s);
    if (s != fmi2DoStepStatus) return bad_status_kind(INST, "fmi2GetStatus", s);
    *value = (fmi2Status)INST->s.last_do_step_status;
    return fmi2OK;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    CS_CHECK(MASK_STATUS, "fmi2GetRealStatus");
    if (!value) return bad_status_kind(INST, "fmi2GetRealStatus (value is NULL)", s);
    if (s != fmi2LastSuccessfulTime) return bad_status_kind(INST, "fmi2GetRealStatus", s);
    *value = INST->s.last_successful_time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    CS_CHECK(MASK_STATUS, "fmi2GetIntegerStatus");
    (void)value;
    return bad_status_kind(INST, "fmi2GetIntegerStatus", s);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    CS_CHECK(MASK_STATUS, "fmi2GetBooleanStatus");
    if (!value) return bad_status_kind(INST, "fmi2GetBooleanStatus (value is NULL)", s);
    if (s != fmi2Terminated) return bad_status_kind(INST, "fmi2GetBooleanStatus", s);
    *value = fmi2False; /* the slave never asks to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    CS_CHECK(MASK_STATUS, "fmi2GetStringStatus");
    (void)value;
    return bad_status_kind(INST, "fmi2GetStringStatus", s);
}
