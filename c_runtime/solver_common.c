/* solver_common.c -- right-hand side with input extrapolation, Jacobian
 * (exact or finite differences), error norm and a dense LU solve used by the
 * Co-Simulation solvers. */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "solver.h"

void fmugen_inputs_at(const fmugen_instance *inst, double t0, const double *u0, double t, double *out)
{
    const int nu = inst->model->nu;
    const double dt = t - t0;
    for (int i = 0; i < nu; i++)
        out[i] = inst->dddu[i] != 0.0
                     ? u0[i] + (inst->du[i] + (0.5 * inst->ddu[i] + inst->dddu[i] * dt / 6.0) * dt) * dt
                 : inst->ddu[i] != 0.0 ? u0[i] + (inst->du[i] + 0.5 * inst->ddu[i] * dt) * dt
                 : inst->du[i] != 0.0 ? u0[i] + inst->du[i] * dt : u0[i];
}

int fmugen_ode_rhs(fmugen_ode *ode, double t, const double *x, double *dx)
{
    fmugen_instance *inst = ode->inst;
    const fmugen_model_def *m = inst->model;
    fmugen_ode_inputs(ode, t, ode->u_work);
    inst->s.n_rhs++;
    int rc = m->evaluate(inst->p, t, x, ode->u_work, dx, NULL);
    if (rc == FMUGEN_OK && !fmugen_all_finite(dx, m->nx)) rc = FMUGEN_NOT_FINITE;
    if (rc != FMUGEN_OK) ode->model_code = rc;
    return rc;
}

int fmugen_ode_jacobian(fmugen_ode *ode, double t, const double *x, const double *fx, double *J, double *tmp)
{
    fmugen_instance *inst = ode->inst;
    const fmugen_model_def *m = inst->model;
    const int n = m->nx;
    inst->s.n_jac++;
    if (m->has_jacobian && m->jacobian) {
        fmugen_ode_inputs(ode, t, ode->u_work);
        int rc = m->jacobian(inst->p, t, x, ode->u_work, J, NULL, NULL, NULL);
        if (rc == FMUGEN_OK && !fmugen_all_finite(J, n * n)) rc = FMUGEN_NOT_FINITE;
        if (rc != FMUGEN_OK) ode->model_code = rc;
        return rc;
    }
    /* forward differences, column j perturbed by sqrt(eps) * max(|x_j|, nominal_j) */
    double *xp = tmp, *fp = tmp + n;
    memcpy(xp, x, (size_t)n * sizeof(double));
    for (int j = 0; j < n; j++) {
        double scale = fabs(x[j]) > m->x_nominal[j] ? fabs(x[j]) : m->x_nominal[j];
        double delta = sqrt(DBL_EPSILON) * (scale > 0 ? scale : 1.0);
        xp[j] = x[j] + delta;
        delta = xp[j] - x[j]; /* the step actually representable */
        int rc = fmugen_ode_rhs(ode, t, xp, fp);
        xp[j] = x[j];
        if (rc != FMUGEN_OK) return rc;
        for (int i = 0; i < n; i++) J[i * n + j] = (fp[i] - fx[i]) / delta;
    }
    return FMUGEN_OK;
}

double fmugen_error_norm(const fmugen_instance *inst, const double *e, const double *a, const double *b)
{
    const fmugen_model_def *m = inst->model;
    const int n = m->nx;
    if (n == 0) return 0.0;
    const double rtol = inst->s.rt[FMUGEN_RT_RTOL], atol = inst->s.rt[FMUGEN_RT_ATOL];
    double sum = 0.0;
    for (int i = 0; i < n; i++) {
        double mag = fabs(a[i]) > fabs(b[i]) ? fabs(a[i]) : fabs(b[i]);
        double sk = atol * m->x_nominal[i] + rtol * mag;
        double r = e[i] / sk;
        sum += r * r;
    }
    return sqrt(sum / n);
}

int fmugen_lu_factor(int n, double *A, int *ipiv)
{
    for (int k = 0; k < n; k++) {
        int p = k;
        double big = fabs(A[k * n + k]);
        for (int i = k + 1; i < n; i++)
            if (fabs(A[i * n + k]) > big) { big = fabs(A[i * n + k]); p = i; }
        ipiv[k] = p;
        if (!(big > 0.0) || !isfinite(big)) return 1;
        if (p != k)
            for (int j = 0; j < n; j++) { double t = A[k * n + j]; A[k * n + j] = A[p * n + j]; A[p * n + j] = t; }
        const double inv = 1.0 / A[k * n + k];
        for (int i = k + 1; i < n; i++) {
            double l = A[i * n + k] * inv;
            A[i * n + k] = l;
            if (l != 0.0)
                for (int j = k + 1; j < n; j++) A[i * n + j] -= l * A[k * n + j];
        }
    }
    return 0;
}

void fmugen_lu_solve(int n, const double *LU, const int *ipiv, double *b)
{
    for (int k = 0; k < n; k++) {
        int p = ipiv[k];
        if (p != k) { double t = b[k]; b[k] = b[p]; b[p] = t; }
    }
    for (int i = 0; i < n; i++) {
        double s = b[i];
        for (int j = 0; j < i; j++) s -= LU[i * n + j] * b[j];
        b[i] = s;
    }
    for (int i = n - 1; i >= 0; i--) {
        double s = b[i];
        for (int j = i + 1; j < n; j++) s -= LU[i * n + j] * b[j];
        b[i] = s / LU[i * n + i];
    }
}

/* ---- checks after a communication step ---- */

/* Most range messages logged per instance: a model that stays outside its
 * range for the rest of a run must not flood the log (the step status still
 * says fmi2Warning at every such step). */
#define FMUGEN_MAX_RANGE_MESSAGES 20

/* Index of the first value of v[0..n) outside [lo, hi] (NULL bounds: none), or -1 */
static int first_out_of_range(const double *v, const double *lo, const double *hi, int n)
{
    if (!lo && !hi) return -1;
    for (int i = 0; i < n; i++)
        if ((lo && v[i] < lo[i]) || (hi && v[i] > hi[i])) return i;
    return -1;
}

fmi2Status fmugen_check_step_result(fmugen_instance *inst, const char *fn, char *msg, size_t n)
{
    const fmugen_model_def *m = inst->model;
    for (int i = 0; i < m->nx; i++) {
        if (!isfinite(inst->x[i])) {
            snprintf(msg, n, "state %s = %g is not finite at t = %.17g", m->x_names[i], inst->x[i], inst->s.time);
            return fmi2Discard;
        }
    }
    fmugen_invalidate(inst);
    if (!inst->cache_valid) {
        int rc = m->evaluate(inst->p, inst->s.time, inst->x, inst->u, inst->dx_cache, inst->y_cache);
        int bad_y = -1, bad_dx = -1;
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < m->ny && bad_y < 0; i++) if (!isfinite(inst->y_cache[i])) bad_y = i;
            for (int i = 0; i < m->nx && bad_dx < 0; i++) if (!isfinite(inst->dx_cache[i])) bad_dx = i;
            if (bad_y >= 0 || bad_dx >= 0) rc = FMUGEN_NOT_FINITE;
        }
        inst->cache_status = rc;
        inst->cache_valid = 1;
        if (rc != FMUGEN_OK) {
            if (bad_y >= 0)
                snprintf(msg, n, "output %s = %g is not finite at t = %.17g", m->y_names[bad_y],
                         inst->y_cache[bad_y], inst->s.time);
            else if (bad_dx >= 0)
                snprintf(msg, n, "derivative der(%s) = %g is not finite at t = %.17g", m->x_names[bad_dx],
                         inst->dx_cache[bad_dx], inst->s.time);
            else
                snprintf(msg, n, "the model cannot be evaluated at the end point t = %.17g: %s", inst->s.time,
                         fmugen_model_status_text(rc));
            return fmi2Discard;
        }
    }
    return fmugen_check_ranges(inst, fn, msg, n);
}

fmi2Status fmugen_check_ranges(fmugen_instance *inst, const char *fn, char *msg, size_t n)
{
    /* validity ranges: reported, by default as a warning (the result may
     * still be what the user wants, e.g. a pressure peak), as a failure when
     * the runtime parameter range_check asks for it */
    const fmugen_model_def *m = inst->model;
    const int action = fmugen_range_action(inst);
    if (action == FMUGEN_RANGE_IGNORE) return fmi2OK;
    struct { const char *what; const char *const *names; const double *v, *lo, *hi; int n; } groups[3] = {
        {"state", m->x_names, inst->x, m->x_min, m->x_max, m->nx},
        {"input", m->u_names, inst->u, m->u_min, m->u_max, m->nu},
        {"output", m->y_names, inst->y_cache, m->y_min, m->y_max, m->ny},
    };
    for (int g = 0; g < 3; g++) {
        int i = first_out_of_range(groups[g].v, groups[g].lo, groups[g].hi, groups[g].n);
        if (i < 0) continue;
        snprintf(msg, n, "%s %s = %.9g left its validity range [%.9g, %.9g] at t = %.17g", groups[g].what,
                 groups[g].names[i], groups[g].v[i], groups[g].lo ? groups[g].lo[i] : -HUGE_VAL,
                 groups[g].hi ? groups[g].hi[i] : HUGE_VAL, inst->s.time);
        if (action == FMUGEN_RANGE_ERROR) return fmi2Discard;
        if (inst->range_messages < FMUGEN_MAX_RANGE_MESSAGES) {
            inst->range_messages++;
            fmugen_log(inst, fmi2Warning, FMUGEN_LOG_STATUS_WARNING, "%s: %s (the model is not valid there%s)", fn,
                       msg, inst->range_messages == FMUGEN_MAX_RANGE_MESSAGES ? "; further range warnings are "
                                                                                  "not logged" : "");
        }
        return fmi2Warning;
    }
    return fmi2OK;
}
