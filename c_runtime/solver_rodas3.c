/*
 * solver_rodas3.c -- RODAS3, a linearly implicit (Rosenbrock) method for stiff
 * models: 4 stages, order 3 with an embedded order-2 solution, stiffly
 * accurate and L-stable (Sandu, Verwer, Blom, Spee, Carmichael & Potra 1997,
 * "Benchmarking stiff ODE solvers for atmospheric chemistry problems II:
 * Rosenbrock solvers", Atmos. Environ. 31; the scheme form of Hairer & Wanner,
 * "Solving ODEs II", sec. IV.7).
 *
 * With J = df/dx and f_t = df/dt at (t, x), each stage i solves
 *     (I/(h gamma) - J) k_i = f(t + alpha_i h, x + sum_j a_ij k_j)
 *                              + sum_j c_ij k_j / h + h gamma_i f_t
 * with one LU factorisation per step; x_new = x + sum m_i k_i and the error
 * estimate is x_new - x_embedded = k_4.  No Newton iteration: the exact
 * Jacobian (the model's, or forward differences when it has none) makes the
 * method L-stable, so steps far beyond the explicit stability limit stay
 * stable.  f_t is a forward difference in t (zero, exactly, when f does not
 * depend on t and no input derivatives are set).
 *
 * Step control: err = 4 x RMS of k_4 weighted by atol x_nominal_i + rtol
 * max(|x|, |x_new|) (aiming at a quarter of the tolerance, see below);
 * accepted when err <= 1; h_new = h min(6, max(0.2, 0.9 err^(-1/3)))
 * (no growth right after a rejection, h/10 after two).  J and f are reused
 * when a step is rejected.  A singular iteration matrix or a failed model
 * evaluation at a trial point shrinks the step by 4.
 */
#include <float.h>

/* error estimate multiplier: the controller keeps the estimate at 1/4 of the tolerance */
#define RODAS3_TOLERANCE_SHARE 4.0
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "solver.h"

static const double gam = 0.5;
/* a_ij and c_ij (strictly lower triangular), m_i, alpha_i, gamma_i */
static const double A31 = 2.0, A32 = 0.0, A41 = 2.0, A42 = 0.0, A43 = 1.0;
static const double C21 = 4.0, C31 = 1.0, C32 = -1.0, C41 = 1.0, C42 = -1.0, C43 = -8.0 / 3.0;
static const double M1 = 2.0, M2 = 0.0, M3 = 1.0, M4 = 1.0;
static const double G1 = 0.5, G2 = 1.5; /* gamma_3 = gamma_4 = 0; alpha = (0, 0, 1, 1) */

int fmugen_solve_rodas3(fmugen_ode *ode, double t_end, char *msg, size_t msgn)
{
    fmugen_instance *inst = ode->inst;
    const int n = inst->model->nx;
    double *x = inst->x;
    if (n == 0) { inst->s.time = t_end; return FMUGEN_SOLVER_OK; }
    double *w = inst->work;
    double *f0 = w, *ft = w + n, *k1 = w + 2 * n, *k2 = w + 3 * n, *k3 = w + 4 * n, *k4 = w + 5 * n;
    double *ys = w + 6 * n, *fs = w + 7 * n, *tmp = w + 8 * n; /* tmp: 2n */
    double *J = w + 10 * n, *G = J + n * n;
    int *ipiv = inst->ipiv;
    const double hmax = inst->s.rt[FMUGEN_RT_MAX_STEP] > 0 ? inst->s.rt[FMUGEN_RT_MAX_STEP] : INFINITY;
    double t = inst->s.time;
    double h = inst->s.h_next;
    int have_jac = 0, reject_last = 0, reject_more = 0, steps = 0;
    const char *last_problem = NULL;
    int last_model_fail = FMUGEN_OK;

    inst->s.fsal_valid = 0; /* x changes: the Dormand-Prince f is stale */
    while (t < t_end) {
        if (!have_jac) {
            int rc = fmugen_ode_rhs(ode, t, x, f0);
            if (rc == FMUGEN_OK) rc = fmugen_ode_jacobian(ode, t, x, f0, J, tmp);
            if (rc == FMUGEN_OK) {
                /* forward difference in t with x fixed (one evaluation; it
                 * only corrects the O(h^2) time-dependence term) */
                volatile double tp = t + sqrt(DBL_EPSILON) * fmax(fabs(t), 1.0);
                const double dt = tp - t;
                rc = fmugen_ode_rhs(ode, tp, x, tmp);
                if (rc == FMUGEN_OK)
                    for (int i = 0; i < n; i++) ft[i] = (tmp[i] - f0[i]) / dt;
                else { /* the model is not defined at t + dt: treat it as autonomous */
                    for (int i = 0; i < n; i++) ft[i] = 0.0;
                    rc = FMUGEN_OK;
                }
            }
            if (rc != FMUGEN_OK) {
                snprintf(msg, msgn, "RODAS3: model evaluation failed at t = %.17g: %s", t,
                         fmugen_model_status_text(rc));
                return FMUGEN_SOLVER_FAILED;
            }
            have_jac = 1;
            if (!(h > 0)) {
                /* first step: ||f||, weighted by the tolerances, is the inverse
                 * of the time in which x changes by one tolerance unit; the
                 * third root reflects the order-3 local error.  The step
                 * control corrects this guess within a few steps. */
                double fn = fmugen_error_norm(inst, f0, x, x);
                h = fn > 0 ? 0.1 * pow(fn, -1.0 / 3.0) : 1e-3;
                h = fmin(h, fmax(t_end - t, 0.0));
                if (!(h > 0)) h = 1e-6;
            }
        }
        if (steps++ >= FMUGEN_SOLVER_MAX_STEPS) {
            snprintf(msg, msgn, "RODAS3: more than %d internal steps in one communication step (t = %.17g, h = %.3g)",
                     FMUGEN_SOLVER_MAX_STEPS, t, h);
            return FMUGEN_SOLVER_FAILED;
        }
        if (h > hmax) h = hmax;
        double h_prop = h;
        int last = 0;
        if (t + 1.01 * h >= t_end) { h = t_end - t; last = 1; }
        if (!last && h < 16 * DBL_EPSILON * fmax(fabs(t), 1e-300)) {
            if (last_model_fail != FMUGEN_OK)
                snprintf(msg, msgn, "RODAS3: step size underflow at t = %.17g after model evaluation failures (%s)",
                         t, fmugen_model_status_text(last_model_fail));
            else
                snprintf(msg, msgn, "RODAS3: step size underflow (h = %.3g) at t = %.17g%s%s", h, t,
                         last_problem ? ": " : "", last_problem ? last_problem : "");
            return FMUGEN_SOLVER_FAILED;
        }
        /* iteration matrix G = I/(h gamma) - J */
        const double ghinv = 1.0 / (h * gam);
        for (int i = 0; i < n * n; i++) G[i] = -J[i];
        for (int i = 0; i < n; i++) G[i * n + i] += ghinv;
        if (fmugen_lu_factor(n, G, ipiv)) {
            last_problem = "singular iteration matrix";
            inst->s.n_rejected++;
            h *= 0.25;
            reject_last = 1;
            continue;
        }
        const double t_new = last ? t_end : t + h;
        int rc;
        /* stage 1 */
        for (int i = 0; i < n; i++) k1[i] = f0[i] + h * G1 * ft[i];
        fmugen_lu_solve(n, G, ipiv, k1);
        /* stage 2: same evaluation point as stage 1 (a_2j = 0, alpha_2 = 0) */
        for (int i = 0; i < n; i++) k2[i] = f0[i] + C21 * k1[i] / h + h * G2 * ft[i];
        fmugen_lu_solve(n, G, ipiv, k2);
        /* stage 3 at t + h */
        for (int i = 0; i < n; i++) ys[i] = x[i] + A31 * k1[i] + A32 * k2[i];
        rc = fmugen_ode_rhs(ode, t_new, ys, fs);
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < n; i++) k3[i] = fs[i] + (C31 * k1[i] + C32 * k2[i]) / h;
            fmugen_lu_solve(n, G, ipiv, k3);
            /* stage 4 at t + h */
            for (int i = 0; i < n; i++) ys[i] = x[i] + A41 * k1[i] + A42 * k2[i] + A43 * k3[i];
            rc = fmugen_ode_rhs(ode, t_new, ys, fs);
        }
        if (rc != FMUGEN_OK) {
            last_model_fail = rc;
            inst->s.n_rejected++;
            h *= 0.25;
            reject_last = 1;
            continue;
        }
        for (int i = 0; i < n; i++) k4[i] = fs[i] + (C41 * k1[i] + C42 * k2[i] + C43 * k3[i]) / h;
        fmugen_lu_solve(n, G, ipiv, k4);
        for (int i = 0; i < n; i++) ys[i] = x[i] + M1 * k1[i] + M2 * k2[i] + M3 * k3[i] + M4 * k4[i];
        /* The embedded estimate is the order-2/order-3 difference, an RMS over
         * all states: on the PUMA and Van der Pol its global error ran up to
         * 12x the tolerance, so the controller aims at a quarter of it. */
        double e = RODAS3_TOLERANCE_SHARE * fmugen_error_norm(inst, k4, x, ys);
        if (!isfinite(e) || !fmugen_all_finite(ys, n)) {
            last_problem = "non-finite stage values";
            inst->s.n_rejected++;
            h *= 0.25;
            reject_last = 1;
            continue;
        }
        double fac = fmin(6.0, fmax(0.2, 0.9 * pow(fmax(e, 1e-10), -1.0 / 3.0)));
        double hnew = h * fac;
        if (e <= 1.0) {
            if (reject_last) hnew = fmin(hnew, h);
            reject_last = reject_more = 0;
            if (inst->model->nz) { /* a state event inside the step: stop just after it */
                const int ev = fmugen_step_event(ode, t, x, f0, t_new, ys, NULL, NULL, msg, msgn);
                if (ev < 0) return FMUGEN_SOLVER_FAILED;
                if (ev > 0) {
                    inst->s.n_steps++;
                    inst->s.h_next = fmin(hnew, h);
                    return FMUGEN_SOLVER_EVENT;
                }
            }
            memcpy(x, ys, (size_t)n * sizeof(double));
            t = t_new;
            inst->s.time = t;
            inst->s.n_steps++;
            have_jac = 0;
            last_model_fail = FMUGEN_OK;
            last_problem = NULL;
            h = last ? fmax(hnew, h_prop) : hnew;
            inst->s.h_next = h;
            if (fmugen_step_accepted(ode)) return FMUGEN_SOLVER_EARLY;
        } else {
            reject_more = reject_last;
            reject_last = 1;
            h = reject_more ? h * 0.1 : hnew;
            inst->s.n_rejected++;
        }
    }
    return FMUGEN_SOLVER_OK;
}
