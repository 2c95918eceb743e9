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
 *
 * Stability limit: at the start of the first communication step, and again
 * at the start of one after every RK4_ESTIMATE_EVERY steps (so that a limit
 * that changes along the trajectory is followed, at the cost of one Jacobian
 * per 100 steps -- about 400 f evaluations), the dominant eigenvalue lambda
 * of df/dx (the model's exact Jacobian, or differences) is estimated, and
 * the largest stable step is h_max = r(arg lambda) / |lambda|,
 * r the distance from 0 to the boundary of RK4's stability region
 * |1 + z + z^2/2 + z^3/6 + z^4/24| = 1 along the ray of lambda (2.785 on the
 * negative real axis, 2.828 on the imaginary axis, 2.62 at 120 degrees).
 * A communication step whose RK4 step is above it is refused before any
 * step is taken (fmi2Discard, the state kept at the communication point)
 * with the numbers, e.g. "h = 60 us exceeds the RK4 stability limit ~ 55.7 us
 * (largest |lambda| = 5e+04 1/s)": its result would be finite for a while
 * and wrong, and a method must not answer fmi2OK about a step its own
 * estimate calls unstable.  Between two estimates a limit crossed on a
 * nonlinear trajectory shows as a blow-up, whose failure message repeats the
 * first estimate's numbers.
 *
 * The eigenvalue: power iteration on A = D^-1 J D (D = diag(x_nominal), so
 * that pressures and angles weigh alike), then a Rayleigh-Ritz fit on the
 * Krylov pair (v, A v, A^2 v): A^2 v ~ a A v + b v gives lambda^2 = a lambda
 * + b, which captures a dominant complex pair as well as a real eigenvalue.
 */
#include <complex.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "solver.h"

/* RK4 steps between two estimates of the stability limit */
#define RK4_ESTIMATE_EVERY 100

/* Distance from 0 to the boundary of RK4's stability region along the ray
 * of direction d (|d| = 1, Re d < 0): the first r with |R(r d)| > 1, by a scan
 * (the region is not star-shaped in general) and bisection. */
static double rk4_boundary(double complex d)
{
    const int nscan = 700;
    double lo = 0, hi = 0;
    for (int k = 1; k <= nscan; k++) {
        double r = 3.5 * k / nscan;
        double complex z = r * d;
        if (cabs(1 + z + z * z / 2 + z * z * z / 6 + z * z * z * z / 24) > 1 + 1e-13) { hi = r; break; }
        lo = r;
    }
    if (hi == 0) return lo;
    for (int it = 0; it < 50; it++) {
        double mid = 0.5 * (lo + hi);
        double complex z = mid * d;
        if (cabs(1 + z + z * z / 2 + z * z * z / 6 + z * z * z * z / 24) > 1 + 1e-13) hi = mid; else lo = mid;
    }
    return lo;
}

static double dot(int n, const double *a, const double *b)
{
    double s = 0;
    for (int i = 0; i < n; i++) s += a[i] * b[i];
    return s;
}

/* y = A x with A = D^-1 J D (see the header) */
static void scaled_matvec(const fmugen_model_def *m, const double *J, const double *x, double *y)
{
    const int n = m->nx;
    for (int i = 0; i < n; i++) {
        double s = 0;
        for (int j = 0; j < n; j++) s += J[i * n + j] * m->x_nominal[j] * x[j];
        y[i] = s / m->x_nominal[i];
    }
}

/* Dominant eigenvalue of J (n x n) into *lam; returns 0, or 1 when no
 * estimate is possible (a non-finite iterate).  v, w, z: n doubles each. */
static int dominant_eigenvalue(const fmugen_model_def *m, const double *J, double *v, double *w, double *z,
                               double complex *lam)
{
    const int n = m->nx;
    for (int i = 0; i < n; i++) v[i] = 1.0 + 0.5 * sin(1.7 * i + 0.3); /* not orthogonal to anything simple */
    double nv = sqrt(dot(n, v, v));
    for (int i = 0; i < n; i++) v[i] /= nv;
    for (int round = 0; round < 4; round++) {
        for (int it = 0; it < 40; it++) {
            scaled_matvec(m, J, v, w);
            double nw = sqrt(dot(n, w, w));
            if (!isfinite(nw)) return 1;
            if (nw == 0) { *lam = 0; return 0; }
            for (int i = 0; i < n; i++) v[i] = w[i] / nw;
        }
        scaled_matvec(m, J, v, w);
        scaled_matvec(m, J, w, z);
        const double ww = dot(n, w, w), wv = dot(n, w, v), vv = dot(n, v, v), wz = dot(n, w, z),
                     vz = dot(n, v, z), zz = dot(n, z, z);
        const double det = ww * vv - wv * wv;
        if (!(zz > 0)) { *lam = 0; return 0; }
        if (det <= 1e-14 * ww * vv) { /* v is an eigenvector: a real eigenvalue */
            *lam = wv / vv;
            return 0;
        }
        const double a = (wz * vv - vz * wv) / det, b = (ww * vz - wv * wz) / det;
        double res = 0;
        for (int i = 0; i < n; i++) { double r = z[i] - a * w[i] - b * v[i]; res += r * r; }
        const double disc = a * a + 4 * b;
        double complex l1, l2;
        if (disc >= 0) { l1 = 0.5 * (a + sqrt(disc)); l2 = 0.5 * (a - sqrt(disc)); }
        else { l1 = 0.5 * a + 0.5 * I * sqrt(-disc); l2 = conj(l1); }
        *lam = cabs(l1) >= cabs(l2) ? l1 : l2;
        if (res <= 1e-6 * zz) return 0; /* the pair spans an invariant subspace */
    }
    /* slow convergence (nearly equal moduli): the growth rate is still |lambda| */
    *lam = -sqrt(dot(n, z, z) / dot(n, w, w));
    return 0;
}

/* "60 us", "1.5 ms", "0.2 s" */
static void fmt_time(char *buf, size_t n, double h)
{
    if (h < 1e-3) snprintf(buf, n, "%.3g us", h * 1e6);
    else if (h < 1) snprintf(buf, n, "%.3g ms", h * 1e3);
    else snprintf(buf, n, "%.3g s", h);
}

/* Estimates the stability limit at (t, x) with f(t, x) = fx.  Returns 1, with
 * the numbers in msg, when h exceeds it: the step must not be taken (its
 * result would be finite for a while but wrong, and grow without bound). */
static int check_stability_limit(fmugen_ode *ode, double t, const double *fx, double h, double *w, char *msg,
                                 size_t msgn)
{
    fmugen_instance *inst = ode->inst;
    const fmugen_model_def *m = inst->model;
    const int n = m->nx;
    double *J = w, *v = w + (size_t)n * n, *wv = v + n, *z = wv + n, *tmp = z + n;
    if (fmugen_ode_jacobian(ode, t, inst->x, fx, J, tmp) != FMUGEN_OK) return 0;
    double complex lam;
    if (dominant_eigenvalue(m, J, v, wv, z, &lam)) return 0;
    const double mod = cabs(lam);
    if (!(mod > 0) || !isfinite(mod)) { inst->s.rk4_h_limit = 0; inst->s.rk4_lambda = 0; return 0; }
    const double complex d = lam / mod;
    double r;
    if (creal(d) < -0.05) r = rk4_boundary(d);
    else if (creal(d) < 0.05) r = 2.0 * sqrt(2.0); /* (nearly) undamped: the imaginary-axis limit */
    else { inst->s.rk4_h_limit = 0; inst->s.rk4_lambda = mod; return 0; } /* a growing mode: no step is stable */
    inst->s.rk4_h_limit = r / mod;
    inst->s.rk4_lambda = mod;
    const double lim = inst->s.rk4_h_limit;
    if (!(h > lim)) return 0;
    char hb[32], lb[32];
    fmt_time(hb, sizeof hb, h);
    fmt_time(lb, sizeof lb, lim);
    if (inst->s.rk4_warned_limit == 0) {
        inst->s.rk4_first_limit = lim;
        inst->s.rk4_first_lambda = mod;
        inst->s.rk4_first_time = t;
    }
    inst->s.rk4_warned_limit = lim;
    snprintf(msg, msgn,
             "RK4: h = %s exceeds the RK4 stability limit ~ %s (largest |lambda| = %.3g 1/s, lambda = %.4g%+.4gi, "
             "at t = %.6g): the step was not taken, its result would grow without bound; use fixed_step < %.3g "
             "or the implicit solver (solver.method = 2)",
             hb, lb, mod, creal(lam), cimag(lam), t, lim);
    return 1;
}

/* "h = 60 us exceeds the RK4 stability limit ~ 55.7 us found at t = 0, ..." (the
 * first warning's numbers: those of a state not yet blown up), or the last
 * estimate, or the plain hint */
static void limit_text(const fmugen_instance *inst, double h, char *buf, size_t n)
{
    if (inst->s.rk4_first_limit > 0) {
        char hb[32], lb[32];
        fmt_time(hb, sizeof hb, h);
        fmt_time(lb, sizeof lb, inst->s.rk4_first_limit);
        snprintf(buf, n, "h = %s exceeds the RK4 stability limit ~ %s found at t = %.6g, largest |lambda| = %.3g "
                 "1/s", hb, lb, inst->s.rk4_first_time, inst->s.rk4_first_lambda);
    } else if (inst->s.rk4_h_limit > 0) {
        char hb[32], lb[32];
        fmt_time(hb, sizeof hb, h);
        fmt_time(lb, sizeof lb, inst->s.rk4_h_limit);
        snprintf(buf, n, "h = %s %s the RK4 stability limit ~ %s, largest |lambda| = %.3g 1/s", hb,
                 h > inst->s.rk4_h_limit ? "exceeds" : "is within", lb, inst->s.rk4_lambda);
    } else {
        snprintf(buf, n, "the fixed step probably exceeds the stability limit");
    }
}

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
        if (rc == FMUGEN_OK && s == 0 && inst->s.n_steps >= inst->s.rk4_next_estimate) {
            inst->s.rk4_next_estimate = inst->s.n_steps + RK4_ESTIMATE_EVERY;
            /* refused before any step: the state stays at the communication point */
            if (check_stability_limit(ode, t, k1, h, w + 6 * n, msg, msgn)) return FMUGEN_SOLVER_FAILED;
        }
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
        char lim[256];
        if (rc != FMUGEN_OK) limit_text(inst, h, lim, sizeof lim);
        if (rc == FMUGEN_NOT_FINITE) {
            snprintf(msg, msgn, "RK4: the solution became non-finite in the step from t = %.17g with h = %.3g "
                     "(%s)", t, h, lim);
            return FMUGEN_SOLVER_FAILED;
        }
        if (rc != FMUGEN_OK) {
            snprintf(msg, msgn, "RK4: model evaluation failed in the step from t = %.17g with h = %.3g: %s "
                     "(%s)", t, h, fmugen_model_status_text(rc), lim);
            return FMUGEN_SOLVER_FAILED;
        }
        for (int i = 0; i < n; i++) xn[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        for (int i = 0; i < n; i++) {
            if (!isfinite(xn[i])) {
                char lim[256];
                limit_text(inst, h, lim, sizeof lim);
                snprintf(msg, msgn, "RK4: state %s became non-finite in the step from t = %.17g with h = %.3g "
                         "(%s)", inst->model->x_names[i], t, h, lim);
                return FMUGEN_SOLVER_FAILED;
            }
        }
        if (inst->model->nz) { /* a state event inside the step: stop just after it */
            const int ev = fmugen_step_event(ode, t, x, k1, tn, xn, NULL, NULL, msg, msgn);
            if (ev < 0) return FMUGEN_SOLVER_FAILED;
            if (ev > 0) { inst->s.n_steps++; return FMUGEN_SOLVER_EVENT; }
        }
        memcpy(x, xn, (size_t)n * sizeof(double));
        inst->s.time = tn;
        inst->s.n_steps++;
        if (fmugen_step_accepted(ode)) return FMUGEN_SOLVER_EARLY;
    }
    return FMUGEN_SOLVER_OK;
}
