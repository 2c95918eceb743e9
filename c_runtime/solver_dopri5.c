/*
 * solver_dopri5.c -- Dormand-Prince 5(4) explicit Runge-Kutta method with
 * adaptive step size (Dormand & Prince 1980; step-size control as in Hairer,
 * Norsett & Wanner, "Solving ODEs I", sec. II.4 and their code DOPRI5).
 *
 * Order 5 solution, embedded order 4 error estimate, 7 stages of which the
 * last is f at the new point, reused as the first stage of the next step
 * (FSAL, kept in inst->fsal across communication steps while time, x, u and
 * p are unchanged).
 *
 * Error control: err = || e ||, the RMS norm of the local error estimate
 * weighted by sk_i = atol x_nominal_i + rtol max(|x_i|, |x_new_i|); a step is
 * accepted when err <= 1.  The next step is h / fac with the Lund-stabilised
 * (PI) factor fac = err^(0.2 - 0.75 beta) / facold^beta / 0.9, beta = 0.04,
 * bounded to 1/10 <= fac <= 5.  The initial step follows Hairer's hinit.
 * The step is shortened to land exactly on the communication point.
 *
 * Stiffness detection (Hairer & Wanner, "Solving ODEs II", sec. IV.2, and
 * the test in DOPRI5): stages 6 and 7 are both evaluated at t + h, at the
 * points ys and ynew, so
 *     h lambda ~ h ||k7 - k6|| / ||ynew - ys||
 * (norms in units of each state's nominal value) estimates h times the
 * dominant eigenvalue of df/dx along the difference.
 * When it exceeds 3.25 (DOPRI5's stability boundary on the negative real
 * axis is 3.3) on 15 accepted steps without 6 non-stiff ones in between, the
 * step is bounded by stability rather than accuracy: the problem is stiff.
 * Hairer's code tests every 1000th step; this one tests every step (2 n
 * flops), so a user hears it after a few dozen steps, not 100 000.  Each
 * detection counts in solver.stiffness_detected; the first is logged (once
 * per instance) with |lambda| and the suggestion of the implicit solver.
 */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "solver.h"

/* Butcher tableau (Dormand & Prince 1980, RK5(4)7M) */
static const double c2 = 1.0 / 5, c3 = 3.0 / 10, c4 = 4.0 / 5, c5 = 8.0 / 9;
static const double a21 = 1.0 / 5;
static const double a31 = 3.0 / 40, a32 = 9.0 / 40;
static const double a41 = 44.0 / 45, a42 = -56.0 / 15, a43 = 32.0 / 9;
static const double a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561, a54 = -212.0 / 729;
static const double a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247, a64 = 49.0 / 176,
                    a65 = -5103.0 / 18656;
static const double a71 = 35.0 / 384, a73 = 500.0 / 1113, a74 = 125.0 / 192, a75 = -2187.0 / 6784,
                    a76 = 11.0 / 84;
/* error coefficients: 5th minus 4th order weights */
static const double e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920, e5 = -17253.0 / 339200,
                    e6 = 22.0 / 525, e7 = -1.0 / 40;

/* dense output: the fourth-order continuous extension (Hairer, Norsett & Wanner, DOPRI5's contd5) */
static const double d1 = -12715105075.0 / 11282082432.0, d3 = 87487479700.0 / 32700410799.0,
                    d4 = -10690763975.0 / 1880347072.0, d5 = 701980252875.0 / 199316789632.0,
                    d6 = -1453857185.0 / 822651844.0, d7 = 69997945.0 / 29380423.0;

/* Hairer's initial step guess for a method of order iord. */
/* Hairer & Wanner's stiffness test after an accepted step (see the header). */
static void stiffness_test(fmugen_instance *inst, double t, double h, const double *k6, const double *k7,
                           const double *ys, const double *ynew)
{
    const fmugen_model_def *m = inst->model;
    const int n = m->nx;
    double num = 0, den = 0;
    /* in units of each state's nominal value: pressures of 1e7 Pa and angles
     * of 0.1 rad weigh alike, so the ratio estimates the eigenvalue rather
     * than the (non-normal) Jacobian's norm */
    for (int i = 0; i < n; i++) {
        const double df = (k7[i] - k6[i]) / m->x_nominal[i], dy = (ynew[i] - ys[i]) / m->x_nominal[i];
        num += df * df;
        den += dy * dy;
    }
    if (!(den > 0)) return;
    const double lambda = sqrt(num / den), hlamb = h * lambda;
    if (hlamb > 3.25) {
        inst->s.nonstiff_run = 0;
        if (++inst->s.stiff_run == 15) {
            inst->s.n_stiff++;
            if (!inst->s.stiff_logged) {
                inst->s.stiff_logged = 1;
                fmugen_log(inst, fmi2Warning, FMUGEN_LOG_STATUS_WARNING,
                           "Dormand-Prince: the problem is stiff at t = %.6g: 15 steps limited by stability "
                           "(h = %.3g s, estimated dominant |lambda| = %.3g 1/s, h |lambda| = %.2f > 3.25); "
                           "the results stay accurate but cost many steps: use the implicit solver "
                           "(solver.method = 2)", t, h, lambda, hlamb);
            }
        }
    } else if (++inst->s.nonstiff_run == 6) {
        inst->s.stiff_run = 0;
    }
}

static int initial_step(fmugen_ode *ode, double t, const double *x, const double *f0, double hmax, double *y1,
                        double *f1, double *h_out)
{
    const fmugen_instance *inst = ode->inst;
    const fmugen_model_def *m = inst->model;
    const int n = m->nx;
    const double rtol = inst->s.rt[FMUGEN_RT_RTOL], atol = inst->s.rt[FMUGEN_RT_ATOL];
    double dnf = 0, dny = 0;
    for (int i = 0; i < n; i++) {
        double sk = atol * m->x_nominal[i] + rtol * fabs(x[i]);
        dnf += (f0[i] / sk) * (f0[i] / sk);
        dny += (x[i] / sk) * (x[i] / sk);
    }
    double h = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : 0.01 * sqrt(dny / dnf);
    if (h > hmax) h = hmax;
    for (int i = 0; i < n; i++) y1[i] = x[i] + h * f0[i];
    int rc = fmugen_ode_rhs(ode, t + h, y1, f1);
    if (rc != FMUGEN_OK) { *h_out = 0.1 * h; return FMUGEN_OK; } /* let the step control sort it out */
    double der2 = 0;
    for (int i = 0; i < n; i++) {
        double sk = atol * m->x_nominal[i] + rtol * fabs(x[i]);
        der2 += ((f1[i] - f0[i]) / sk) * ((f1[i] - f0[i]) / sk);
    }
    der2 = sqrt(der2) / h;
    double der12 = fmax(der2, sqrt(dnf));
    double h1 = der12 <= 1e-15 ? fmax(1e-6, h * 1e-3) : pow(0.01 / der12, 1.0 / 5.0);
    h = fmin(100 * h, h1);
    /* derivatives near the overflow threshold make the norms infinite and h1
     * zero: start small and let the step control sort it out */
    if (!(h > 0)) h = 1e-6 * fmax(fabs(t), 1.0);
    *h_out = fmin(h, hmax);
    return FMUGEN_OK;
}

int fmugen_solve_dopri5(fmugen_ode *ode, double t_end, char *msg, size_t msgn)
{
    fmugen_instance *inst = ode->inst;
    const int n = inst->model->nx;
    double *x = inst->x;
    if (n == 0) { inst->s.time = t_end; return FMUGEN_SOLVER_OK; }
    double *k1 = inst->fsal, *w = inst->work;
    double *k2 = w, *k3 = w + n, *k4 = w + 2 * n, *k5 = w + 3 * n, *k6 = w + 4 * n, *k7 = w + 5 * n;
    double *ys = w + 6 * n, *ynew = w + 7 * n, *err = w + 8 * n;
    const double hmax = inst->s.rt[FMUGEN_RT_MAX_STEP] > 0 ? inst->s.rt[FMUGEN_RT_MAX_STEP] : INFINITY;
    const double beta = 0.04, expo1 = 0.2 - beta * 0.75, safe = 0.9, facc1 = 5.0, facc2 = 0.1;
    double t = inst->s.time;

    if (!inst->s.fsal_valid) {
        int rc = fmugen_ode_rhs(ode, t, x, k1);
        if (rc != FMUGEN_OK) {
            snprintf(msg, msgn, "Dormand-Prince: model evaluation failed at t = %.17g: %s", t,
                     fmugen_model_status_text(rc));
            return FMUGEN_SOLVER_FAILED;
        }
        inst->s.fsal_valid = 1;
    }
    double h = inst->s.h_next;
    if (!(h > 0)) {
        initial_step(ode, t, x, k1, hmax, k2, k3, &h);
        inst->s.h_next = h;
    }
    int reject = 0, steps = 0;
    int last_model_fail = FMUGEN_OK;
    while (t < t_end) {
        if (steps++ >= FMUGEN_SOLVER_MAX_STEPS) {
            snprintf(msg, msgn, "Dormand-Prince: more than %d internal steps in one communication step (t = %.17g, "
                     "h = %.3g); the model may be stiff: try the implicit solver",
                     FMUGEN_SOLVER_MAX_STEPS, t, h);
            return FMUGEN_SOLVER_FAILED;
        }
        if (h > hmax) h = hmax;
        double h_prop = h;
        int last = 0;
        if (t + 1.01 * h >= t_end) { h = t_end - t; last = 1; }
        if (!last && h < 16 * DBL_EPSILON * fmax(fabs(t), 1e-300)) {
            if (last_model_fail != FMUGEN_OK)
                snprintf(msg, msgn, "Dormand-Prince: step size underflow at t = %.17g after model evaluation "
                         "failures (%s)", t, fmugen_model_status_text(last_model_fail));
            else
                snprintf(msg, msgn, "Dormand-Prince: step size underflow (h = %.3g) at t = %.17g", h, t);
            return FMUGEN_SOLVER_FAILED;
        }
        int rc;
        for (int i = 0; i < n; i++) ys[i] = x[i] + h * a21 * k1[i];
        rc = fmugen_ode_rhs(ode, t + c2 * h, ys, k2);
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < n; i++) ys[i] = x[i] + h * (a31 * k1[i] + a32 * k2[i]);
            rc = fmugen_ode_rhs(ode, t + c3 * h, ys, k3);
        }
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < n; i++) ys[i] = x[i] + h * (a41 * k1[i] + a42 * k2[i] + a43 * k3[i]);
            rc = fmugen_ode_rhs(ode, t + c4 * h, ys, k4);
        }
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < n; i++)
                ys[i] = x[i] + h * (a51 * k1[i] + a52 * k2[i] + a53 * k3[i] + a54 * k4[i]);
            rc = fmugen_ode_rhs(ode, t + c5 * h, ys, k5);
        }
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < n; i++)
                ys[i] = x[i] + h * (a61 * k1[i] + a62 * k2[i] + a63 * k3[i] + a64 * k4[i] + a65 * k5[i]);
            rc = fmugen_ode_rhs(ode, last ? t_end : t + h, ys, k6);
        }
        if (rc == FMUGEN_OK) {
            for (int i = 0; i < n; i++)
                ynew[i] = x[i] + h * (a71 * k1[i] + a73 * k3[i] + a74 * k4[i] + a75 * k5[i] + a76 * k6[i]);
            /* an overflowed state would pass the error test (its weight is
             * infinite too) and be accepted: it is a failed trial instead */
            rc = fmugen_all_finite(ynew, n) ? fmugen_ode_rhs(ode, last ? t_end : t + h, ynew, k7) : FMUGEN_NOT_FINITE;
        }
        if (rc != FMUGEN_OK) {
            /* a trial point outside the model's domain: retry with a smaller step */
            last_model_fail = rc;
            inst->s.n_rejected++;
            h *= 0.25;
            reject = 1;
            continue;
        }
        for (int i = 0; i < n; i++)
            err[i] = h * (e1 * k1[i] + e3 * k3[i] + e4 * k4[i] + e5 * k5[i] + e6 * k6[i] + e7 * k7[i]);
        double e = fmugen_error_norm(inst, err, x, ynew);
        if (!isfinite(e)) {
            inst->s.n_rejected++;
            h *= 0.25;
            reject = 1;
            continue;
        }
        double fac11 = pow(e, expo1);
        if (e <= 1.0) {
            double fac = fac11 / pow(inst->s.facold, beta);
            fac = fmax(facc2, fmin(facc1, fac / safe));
            double hnew = h / fac;
            inst->s.facold = fmax(e, 1e-4);
            if (reject) hnew = fmin(hnew, h);
            /* a step shortened to hit the communication point is no test */
            if (!last) stiffness_test(inst, t, h, k6, k7, ys, ynew);
            if (inst->model->nz) { /* a state event inside the step: stop just after it */
                /* the continuous extension's fourth-order term (Hairer's dense output of DOPRI5), in err:
                 * the error estimate is no longer needed */
                for (int i = 0; i < n; i++)
                    err[i] = h * (d1 * k1[i] + d3 * k3[i] + d4 * k4[i] + d5 * k5[i] + d6 * k6[i] + d7 * k7[i]);
                const int ev = fmugen_step_event(ode, t, x, k1, last ? t_end : t + h, ynew, k7, err, msg, msgn);
                if (ev < 0) return FMUGEN_SOLVER_FAILED;
                if (ev > 0) {
                    inst->s.n_steps++;
                    inst->s.facold = fmax(e, 1e-4);
                    inst->s.h_next = fmin(hnew, h);
                    return FMUGEN_SOLVER_EVENT;
                }
            }
            memcpy(x, ynew, (size_t)n * sizeof(double));
            memcpy(k1, k7, (size_t)n * sizeof(double));
            t = last ? t_end : t + h;
            inst->s.time = t;
            inst->s.n_steps++;
            reject = 0;
            last_model_fail = FMUGEN_OK;
            /* a step shortened to hit the communication point says nothing
             * against the step the controller wanted */
            h = last ? fmax(hnew, h_prop) : hnew;
            inst->s.h_next = h;
            if (fmugen_step_accepted(ode)) return FMUGEN_SOLVER_EARLY;
        } else {
            inst->s.n_rejected++;
            h = h / fmin(facc1, fac11 / safe);
            reject = 1;
        }
    }
    return FMUGEN_SOLVER_OK;
}
