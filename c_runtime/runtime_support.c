/* runtime_support.c -- logging, state checks, variable names and the cached
 * model evaluation shared by the FMI functions of the runtime. */
#if defined(__MINGW32__) && !defined(__USE_MINGW_ANSI_STDIO)
/* MinGW: the C99 printf of its own static library, not msvcrt.dll's, whose
 * vsnprintf knows no %zu (the log messages format sizes with it) */
#define __USE_MINGW_ANSI_STDIO 1
#endif
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include "fmugen_runtime.h"

/* The order is the order of <LogCategories> in modelDescription.xml. */
const char *const fmugen_log_category_names[FMUGEN_LOG_COUNT] = {
    "logEvents", "logStatusWarning", "logStatusError", "logAll"};

const char *fmugen_state_name(int state)
{
    switch (state) {
    case FMUGEN_INSTANTIATED: return "instantiated";
    case FMUGEN_INITIALIZATION_MODE: return "initializationMode";
    case FMUGEN_EVENT_MODE: return "eventMode";
    case FMUGEN_CONTINUOUS_TIME_MODE: return "continuousTimeMode";
    case FMUGEN_STEP_COMPLETE: return "stepComplete";
    case FMUGEN_STEP_FAILED: return "stepFailed";
    case FMUGEN_TERMINATED: return "terminated";
    case FMUGEN_ERROR: return "error";
    default: return "unknown";
    }
}

/* Messages with status warning or worse always reach the logger: they
 * explain a non-OK return and the importer needs them whether or not it
 * asked for debug logging.  fmi2OK messages are debug logging and are sent
 * only when logging is on and their category (or logAll) is enabled. */
void fmugen_log(fmugen_instance *inst, fmi2Status status, fmugen_log_category cat, const char *fmt, ...)
{
    if (!inst || !inst->cb.logger) return;
    if (status == fmi2OK || status == fmi2Pending) {
        if (!inst->logging_on) return;
        if (!inst->log_category_on[cat] && !inst->log_category_on[FMUGEN_LOG_ALL]) return;
    }
    char raw[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(raw, sizeof raw, fmt, ap);
    va_end(ap);
    /* The logger's message is itself a printf format: double every '%' so
     * that importers which format it print the text unchanged. */
    char msg[2 * sizeof raw];
    size_t j = 0;
    for (size_t i = 0; raw[i] && j + 2 < sizeof msg; i++) {
        if (raw[i] == '%') msg[j++] = '%';
        msg[j++] = raw[i];
    }
    msg[j] = '\0';
    inst->cb.logger(inst->cb.componentEnvironment, inst->instance_name, status,
                    fmugen_log_category_names[cat], msg);
}

int fmugen_check_state(fmugen_instance *inst, int mask, const char *fn)
{
    if (!fmugen_live(inst)) return 0; /* NULL or freed: nobody to log to */
    if (inst->s.fmi_state & mask) return 1;
    fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: not allowed in state %s", fn,
               fmugen_state_name(inst->s.fmi_state));
    return 0;
}

static const char *const rt_names[FMUGEN_RT_COUNT] = {"rtol", "atol", "max_step", "fixed_step"};

const char *fmugen_real_name(const fmugen_instance *inst, fmi2ValueReference vr, char *buf, size_t n)
{
    const fmugen_model_def *m = inst->model;
    if (vr < fmugen_vr_der(m)) snprintf(buf, n, "%s", m->x_names[vr]);
    else if (vr < fmugen_vr_u(m)) snprintf(buf, n, "der(%s)", m->x_names[vr - fmugen_vr_der(m)]);
    else if (vr < fmugen_vr_y(m)) snprintf(buf, n, "%s", m->u_names[vr - fmugen_vr_u(m)]);
    else if (vr < fmugen_vr_p(m)) snprintf(buf, n, "%s", m->y_names[vr - fmugen_vr_y(m)]);
    else if (vr < fmugen_vr_rt(m)) snprintf(buf, n, "%s", m->p_names[vr - fmugen_vr_p(m)]);
    else if (vr < fmugen_vr_d(m)) snprintf(buf, n, "%s", rt_names[vr - fmugen_vr_rt(m)]);
    else if (vr < fmugen_vr_event_time(m)) snprintf(buf, n, "%s", m->d_names[vr - fmugen_vr_d(m)]);
    else if (vr < fmugen_vr_end(m)) snprintf(buf, n, "solver.last_event_time");
    else snprintf(buf, n, "<unknown>");
    return buf;
}

void fmugen_invalidate(fmugen_instance *inst)
{
    inst->cache_valid = 0;
}

int fmugen_all_finite(const double *v, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i])) return 0;
    return 1;
}

const char *fmugen_model_status_text(int code)
{
    switch (code) {
    case FMUGEN_OK: return "ok";
    case FMUGEN_NOT_POSITIVE_DEFINITE: return "the mass matrix is not positive definite";
    case FMUGEN_NOT_FINITE: return "a result is NaN or infinite";
    default: return "unknown model error";
    }
}

int fmugen_evaluate_cached(fmugen_instance *inst, const char *fn)
{
    const fmugen_model_def *m = inst->model;
    if (!inst->cache_valid) {
        int rc = m->evaluate(inst->p, inst->s.time, inst->x, inst->u, inst->dx_cache, inst->y_cache);
        if (rc == FMUGEN_OK && !(fmugen_all_finite(inst->dx_cache, m->nx) &&
                                 fmugen_all_finite(inst->y_cache, m->ny)))
            rc = FMUGEN_NOT_FINITE;
        inst->cache_status = rc;
        inst->cache_valid = 1;
    }
    if (inst->cache_status != FMUGEN_OK) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "%s: model evaluation failed at t = %.17g: %s", fn, inst->s.time,
                   fmugen_model_status_text(inst->cache_status));
    }
    return inst->cache_status;
}

/* Start values of the model and defaults of the runtime parameters. */
void fmugen_set_defaults(fmugen_instance *inst)
{
    const fmugen_model_def *m = inst->model;
    memset(inst->vec, 0, inst->n_vec * sizeof(double));
    if (m->nx) memcpy(inst->x, m->x_start, (size_t)m->nx * sizeof(double));
    if (m->nu) memcpy(inst->u, m->u_start, (size_t)m->nu * sizeof(double));
    if (m->np) memcpy(inst->p, m->p_start, (size_t)m->np * sizeof(double));
    if (m->nd) memcpy(inst->p + m->np, m->d_start, (size_t)m->nd * sizeof(double));
    memset(&inst->s, 0, sizeof inst->s);
    inst->s.fmi_state = FMUGEN_INSTANTIATED;
    inst->s.rt[FMUGEN_RT_RTOL] = 1e-6;
    inst->s.rt[FMUGEN_RT_ATOL] = 1e-6;
    inst->s.rt[FMUGEN_RT_MAX_STEP] = 0.0;
    inst->s.rt[FMUGEN_RT_FIXED_STEP] = 0.0;
    inst->s.solver = FMUGEN_SOLVER_DOPRI5;
    if (m->rt_start) memcpy(inst->s.rt, m->rt_start, FMUGEN_RT_COUNT * sizeof(double));
    if (m->solver_start) inst->s.solver = m->solver_start;
    inst->s.range_check = FMUGEN_RANGE_WARN;
    inst->range_messages = 0;
    inst->s.facold = 1e-4;
    inst->s.last_do_step_status = fmi2OK;
    inst->s.last_indicator = -1;
    fmugen_invalidate(inst);
}
