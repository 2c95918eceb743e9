/*
 * solver_rk4.c -- the classical 4th-order Runge-Kutta method with a fixed
 * step, for stability comparisons (it has no error control and is unstable
 * when h |lambda| exceeds about 2.785 for a real eigenvalue lambda).
 *
 * The step is the runtime parameter fixed_step, shortened so that a whole
 * number of steps fills the communication step (m = ceil(H / fixed_step),
 * h = H / m); fixed_step = 0 means one step per communication step.  A state
 * that becomes NaN or infinite ends the communication step with a failure at
 * the last finite point.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "solver.h"

int fmugen_solve_rk4(fmugen_ode *ode, double t_end, char *msg, size_t msgn)
{
    fmugen_instance *inst = ode->inst;
    const int n = inst->model->nx;
    double *x = inst->x;
    const double t_start = inst->s.time;
    if (n == 0) { inst->s.time = t_end; return FMUGEN_SOLVER_OK; }
    double *w = inst->work;
    double *k1 = w, *k2 = w + n, *k3 = w + 2 * n, *k4 = w + 3 * n, *ys = w + 4 * n, *xn = w + 5 * n;
    const double H = t_end - t_start, hf = inst->s.rt[FMUGEN_RT_FIXED_STEP];
    double mreal = hf > 0 ? ceil(H / hf * (1.0 - 1e-12)) : 1.0;
    if (mreal < 1) mreal = 1;
    if (mreal > FMUGEN_SOLVER_MAX_STEPS) {
        snprintf(msg, msgn, "RK4: communication step %.17g needs %.0f steps of fixed_step = %.3g, more than %d",
                 H, mreal, hf, FMUGEN_SOLVER_MAX_STEPS);
        return FMUGEN_SOLVER_FAILED;
    }
    const long m = (long)mreal;
    const double h = H / (double)m;
    inst->s.fsal_valid = 0;
    for (long s = 0; s < m; s++) {
        const double t = t_start + (double)s * h;
        const double tn = (s + 1 == m) ? t_end : t_start + (double)(s + 1) * h;
        int rc = fmugen_ode_rhs(ode, t, x, k1);
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < n; i++) ys[i] = x[i] + 0.5 * h * k1[i];
            rc = fmugen_ode_rhs(ode, t + 0.5 * h, ys, k2);
        }
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < n; i++) ys[i] = x[i] + 0.5 * h * k2[i];
            rc = fmugen_ode_rhs(ode, t + 0.5 * h, ys, k3);
        }
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < n; i++) ys[i] = x[i] + h * k3[i];
            rc = fmugen_ode_rhs(ode, tn, ys, k4);
        }
        if (rc == FMUGEN_NOT_FINITE) {
            snprintf(msg, msgn, "RK4: the solution became non-finite in the step from t = %.17g with h = %.3g "
                     "(the fixed step probably exceeds the stability limit)", t, h);
            return FMUGEN_SOLVER_FAILED;
        }
        if (rc != FMUGEN_OK) {
            snprintf(msg, msgn, "RK4: model evaluation failed in the step from t = %.17g with h = %.3g: %s "
                     "(the fixed step may exceed the stability limit)", t, h, fmugen_model_status_text(rc));
            return FMUGEN_SOLVER_FAILED;
        }
        for (int i = 0; i < n; i++) xn[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        for (int i = 0; i < n; i++) {
            if (!isfinite(xn[i])) {
                snprintf(msg, msgn, "RK4: state %s became non-finite in the step from t = %.17g with h = %.3g "
                         "(the fixed step exceeds the stability limit)", inst->model->x_names[i], t, h);
                return FMUGEN_SOLVER_FAILED;
            }
        }
        memcpy(x, xn, (size_t)n * sizeof(double));
        inst->s.time = tn;
        inst->s.n_steps++;
    }
    return FMUGEN_SOLVER_OK;
}
