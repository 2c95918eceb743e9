/*
 * events.c -- state events of hybrid models (fmugen_model_def.nz, nd, ng > 0).
 *
 * A model with events has event indicators z(t, x, u, p, d), discrete states
 * d (stored after the parameters, constant between events) and guarded
 * assignments ("clauses") that fire at events.  This file holds what Model
 * Exchange and Co-Simulation share:
 *   - the indicators and the domain of each (z > 0 or z <= 0, FMI 2.0 sec. 3.1);
 *   - one round of the clauses (all guards and values from the values before
 *     the round, then the assignments of the firing clauses in order) and the
 *     event iteration: rounds until nothing changes;
 *   - for Co-Simulation, the location of a domain change inside an accepted
 *     internal solver step: root finding on the step's interpolant
 *     (Dormand-Prince's fourth-order continuous extension; the cubic Hermite
 *     interpolant of x and f at both ends for RK4 and RODAS3, exact for
 *     polynomial solutions up to degree 3), Illinois steps safeguarded by bisection,
 *     to FMUGEN_EVENT_TOL x max(1, |t|) in time.  The state is put at the
 *     right end of the final bracket: just after the crossing, where the
 *     indicator has changed its domain (the guards see the new side).
 *
 * Reinitialising a state to the value it has, or a discrete state to its own
 * value, is no change: an iteration ends when a round changes nothing.
 */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "fmugen_runtime.h"
#include "solver.h"

const char *fmugen_indicator_name(const fmugen_instance *inst, int i, char *buf, size_t n)
{
    const fmugen_model_def *m = inst->model;
    if (m->z_names && i >= 0 && i < m->nz) snprintf(buf, n, "z[%d] (%s)", i + 1, m->z_names[i]);
    else snprintf(buf, n, "z[%d]", i + 1);
    return buf;
}

int fmugen_event_indicators(fmugen_instance *inst, double t, const double *x, const double *u, double *z)
{
    const fmugen_model_def *m = inst->model;
    if (m->nz == 0) return FMUGEN_OK;
    if (!m->indicators) return FMUGEN_NOT_FINITE;
    int rc = m->indicators(inst->p, t, x, u, z);
    if (rc == FMUGEN_OK && !fmugen_all_finite(z, m->nz)) rc = FMUGEN_NOT_FINITE;
    return rc;
}

int fmugen_event_remember(fmugen_instance *inst, const double *u)
{
    return fmugen_event_indicators(inst, inst->s.time, inst->x, u, inst->zpre);
}

/* the same value, bit for bit (a -0.0 for 0.0 is no change of a mode) */
static int same(double a, double b) { return a == b; }

int fmugen_event_round(fmugen_instance *inst, const double *u, int *changed, int *x_changed)
{
    const fmugen_model_def *m = inst->model;
    *changed = *x_changed = 0;
    if (m->ng == 0 || !m->update) return FMUGEN_OK;
    double *guard = inst->ev_work + 5 * (size_t)m->nx + 3 * (size_t)m->nz, *value = guard + m->ng;
    int rc = m->update(inst->p, inst->s.time, inst->x, u, guard, value);
    if (rc != FMUGEN_OK) return rc;
    for (int a = 0; a < m->na; a++) {
        if (guard[m->assign_clause[a]] == 0.0) continue;
        if (!isfinite(value[a])) return FMUGEN_NOT_FINITE;
    }
    for (int a = 0; a < m->na; a++) {
        if (guard[m->assign_clause[a]] == 0.0) continue;
        const int tgt = m->assign_target[a];
        double *slot = tgt < m->nd ? &inst->p[m->np + tgt] : &inst->x[tgt - m->nd];
        if (!same(*slot, value[a])) {
            *slot = value[a];
            *changed = 1;
            if (tgt >= m->nd) *x_changed = 1;
        }
    }
    if (*changed) {
        fmugen_invalidate(inst);
        inst->s.fsal_valid = 0;
    }
    return FMUGEN_OK;
}

/* zpre = the indicators a moment after the current point, along the flow.  Just after an event an
 * indicator sits at its zero (the crossing was located to within FMUGEN_EVENT_TOL, or a state was
 * re-initialised onto a boundary); its domain there is the one the trajectory enters: a ball
 * re-initialised upwards at h = -1e-13 is in h > 0.  Taking h <= 0 would hide the next fall below
 * the ground when one internal step spans the whole flight (both ends in h <= 0). */
static int remember_ahead(fmugen_instance *inst, const double *u)
{
    const fmugen_model_def *m = inst->model;
    const int n = m->nx;
    if (m->nz == 0) return FMUGEN_OK;
    double *f = inst->ev_work, *xs = f + n;
    const double t = inst->s.time, delta = 1e3 * FMUGEN_EVENT_TOL * fmax(1.0, fabs(t));
    int rc = n ? m->evaluate(inst->p, t, inst->x, u, f, NULL) : FMUGEN_OK;
    if (rc == FMUGEN_OK && !fmugen_all_finite(f, n)) rc = FMUGEN_NOT_FINITE;
    if (rc != FMUGEN_OK) return rc;
    for (int i = 0; i < n; i++) xs[i] = inst->x[i] + delta * f[i];
    return fmugen_event_indicators(inst, t + delta, xs, u, inst->zpre);
}

int fmugen_event_iteration(fmugen_instance *inst, const double *u, char *msg, size_t n)
{
    const fmugen_model_def *m = inst->model;
    int changed = 0, x_changed = 0, round = 0;
    do {
        if (round++ == FMUGEN_EVENT_MAX_ROUNDS) {
            snprintf(msg, n, "the event iteration at t = %.17g does not converge: the clauses still change a "
                     "discrete state or a state after %d rounds (a clause whose condition its own assignment "
                     "does not make false?)", inst->s.time, FMUGEN_EVENT_MAX_ROUNDS);
            return FMUGEN_NOT_FINITE;
        }
        int rc = fmugen_event_round(inst, u, &changed, &x_changed);
        if (rc != FMUGEN_OK) {
            snprintf(msg, n, "the event update at t = %.17g failed: %s", inst->s.time, fmugen_model_status_text(rc));
            return rc;
        }
    } while (changed);
    int rc = remember_ahead(inst, u);
    if (rc != FMUGEN_OK) {
        snprintf(msg, n, "the event indicators at t = %.17g could not be evaluated after the event: %s",
                 inst->s.time, fmugen_model_status_text(rc));
        return rc;
    }
    (void)m;
    return FMUGEN_OK;
}

/* Has an indicator whose last value was ref crossed to z?  Its domain was z > 0 or z <= 0 (FMI);
 * it has crossed when z lies strictly on the other side: from z > 0 to z < 0, from z <= 0 to z > 0.
 * A value of exactly 0 after a positive one is not yet past the crossing: the point an event is put
 * at is strictly beyond it, so that a guard written with the strict comparison of the other side
 * (|tau| > T_s after T_s - |tau| fell through 0) holds there. */
static int crossed(double ref, double z) { return ref > 0 ? z < 0 : z > 0; }

/* The step's interpolant at theta in [0, 1] into out, in Hairer's form
 *     x0 + th (r2 + (1 - th) (r3 + th (r4 + (1 - th) r5)))
 * with r2 = x1 - x0, r3 = h f0 - r2, r4 = r2 - h f1 - r3: the cubic Hermite
 * interpolant when r5 = 0 (NULL), Dormand-Prince's fourth-order continuous
 * extension when r5 = h sum d_i k_i (solver_dopri5.c). */
static void interpolant(int n, double h, double th, const double *x0, const double *f0, const double *x1,
                        const double *f1, const double *r5, double *out)
{
    const double s = 1.0 - th;
    for (int i = 0; i < n; i++) {
        const double r2 = x1[i] - x0[i], r3 = h * f0[i] - r2, r4 = r2 - h * f1[i] - r3;
        out[i] = x0[i] + th * (r2 + s * (r3 + th * (r4 + (r5 ? s * r5[i] : 0.0))));
    }
}

int fmugen_step_event(fmugen_ode *ode, double t0, const double *x0, const double *f0, double t1, const double *x1,
                      const double *f1, const double *r5, char *msg, size_t msgn)
{
    fmugen_instance *inst = ode->inst;
    const fmugen_model_def *m = inst->model;
    const int n = m->nx, nz = m->nz;
    if (nz == 0) return 0;
    double *w = inst->ev_work;
    double *xa = w, *xm = w + n, *f1buf = w + 2 * n, *xs0 = w + 3 * n, *fs0 = w + 4 * n;
    double *za = w + 5 * n, *zb = za + nz, *zm = zb + nz;
    double *u = ode->u_work;
    int rc;
    /* x0 and f0 may live where the solver writes next: keep copies */
    memcpy(xs0, x0, (size_t)n * sizeof(double));
    memcpy(fs0, f0, (size_t)n * sizeof(double));
    fmugen_ode_inputs(ode, t1, u);
    rc = fmugen_event_indicators(inst, t1, x1, u, zb);
    if (rc != FMUGEN_OK) {
        snprintf(msg, msgn, "event indicators could not be evaluated at t = %.17g: %s", t1,
                 fmugen_model_status_text(rc));
        return -1;
    }
    int any = 0;
    for (int i = 0; i < nz; i++) any |= crossed(inst->zpre[i], zb[i]);
    if (!any) {
        /* the new values are the reference of the next step; an indicator that reached exactly 0 keeps
         * the side it came from until it leaves 0 */
        for (int i = 0; i < nz; i++)
            if (zb[i] != 0.0) inst->zpre[i] = zb[i];
        return 0;
    }
    if (!f1) {
        rc = fmugen_ode_rhs(ode, t1, x1, f1buf);
        if (rc != FMUGEN_OK) {
            snprintf(msg, msgn, "model evaluation failed at t = %.17g while locating an event: %s", t1,
                     fmugen_model_status_text(rc));
            return -1;
        }
        f1 = f1buf;
    }
    memcpy(za, inst->zpre, (size_t)nz * sizeof(double));
    const double *ref = inst->zpre; /* the sides every crossing is measured from */
    const double h = t1 - t0, tol = FMUGEN_EVENT_TOL * fmax(1.0, fabs(t1));
    double a = 0.0, b = 1.0;
    int kept_a = 0, kept_b = 0, first = -1;
    for (int iter = 0; iter < 400 && (b - a) * h > tol; iter++) {
        /* Illinois-type secant estimate from the earliest crossing, safeguarded by
         * bisection when one end has been kept twice in a row */
        double th = b;
        for (int i = 0; i < nz; i++) {
            if (!crossed(ref[i], zb[i])) continue;
            const double d = za[i] - zb[i];
            double s = d != 0 ? za[i] / d : 0.5;
            if (!(s >= 0.0 && s <= 1.0)) s = 0.5;
            const double ti = a + (b - a) * s;
            if (ti < th) th = ti;
        }
        if (kept_a >= 2 || kept_b >= 2) th = 0.5 * (a + b);
        const double lo = a + 0.01 * (b - a), hi = b - 0.01 * (b - a);
        if (th < lo) th = lo;
        if (th > hi) th = hi;
        interpolant(n, h, th, xs0, fs0, x1, f1, r5, xm);
        const double tm = t0 + th * h;
        fmugen_ode_inputs(ode, tm, u);
        rc = fmugen_event_indicators(inst, tm, xm, u, zm);
        if (rc != FMUGEN_OK) {
            snprintf(msg, msgn, "event indicators could not be evaluated at t = %.17g while locating an event: %s",
                     tm, fmugen_model_status_text(rc));
            return -1;
        }
        int left = 0;
        for (int i = 0; i < nz; i++) left |= crossed(ref[i], zm[i]);
        if (left) { /* a crossing in [a, th] */
            b = th;
            memcpy(zb, zm, (size_t)nz * sizeof(double));
            kept_a++;
            kept_b = 0;
        } else {
            a = th;
            memcpy(za, zm, (size_t)nz * sizeof(double));
            kept_b++;
            kept_a = 0;
        }
    }
    /* the earliest indicator that changed its domain over the final bracket */
    for (int i = 0; i < nz && first < 0; i++)
        if (crossed(ref[i], zb[i])) first = i;
    inst->s.last_indicator = first;
    const double te = b >= 1.0 ? t1 : t0 + b * h;
    if (b >= 1.0) memcpy(xa, x1, (size_t)n * sizeof(double));
    else interpolant(n, h, b, xs0, fs0, x1, f1, r5, xa);
    memcpy(inst->x, xa, (size_t)n * sizeof(double));
    inst->s.time = te;
    memcpy(inst->zpre, zb, (size_t)nz * sizeof(double));
    fmugen_invalidate(inst);
    inst->s.fsal_valid = 0;
    return 1;
}

/* ---- clocks: time events of sampled components ---------------------------------------------- */

/* a tick within this of t is at t (a sample instant computed as offset + j period carries round-off) */
static double tick_tol(double t, double period) { return fmax(1e-9 * period, 8 * DBL_EPSILON * fabs(t)); }

int fmugen_next_tick(fmugen_instance *inst, double t, double *next, int *at_t)
{
    const fmugen_model_def *m = inst->model;
    *next = HUGE_VAL;
    *at_t = 0;
    if (m->ns == 0) return FMUGEN_OK;
    double *per = inst->ev_work + 5 * (size_t)m->nx + 3 * (size_t)m->nz + m->ng + m->na, *off = per + m->ns;
    int rc = m->clocks(inst->p, per, off);
    if (rc != FMUGEN_OK) return rc;
    for (int k = 0; k < m->ns; k++) {
        const double P = per[k], O = off[k];
        if (!(P > 0) || !isfinite(P) || !isfinite(O)) return FMUGEN_NOT_FINITE;
        const double tol = tick_tol(t, P), j = floor((t - O) / P + 0.5);
        double nk;
        if (t < O - tol) {
            nk = O;
        } else if (fabs(O + j * P - t) <= tol) {
            *at_t = 1;
            nk = O + (j + 1) * P;
        } else {
            nk = O + ceil((t - O) / P) * P;
        }
        if (nk < *next) *next = nk;
    }
    return FMUGEN_OK;
}

/* Set the tick flags of the clocks that tick at t to on (1) or all to 0. */
static void set_ticks(fmugen_instance *inst, double t, int on)
{
    const fmugen_model_def *m = inst->model;
    double *per = inst->ev_work + 5 * (size_t)m->nx + 3 * (size_t)m->nz + m->ng + m->na, *off = per + m->ns;
    for (int k = 0; k < m->ns; k++) {
        double v = 0.0;
        if (on) {
            const double P = per[k], O = off[k], j = floor((t - O) / P + 0.5);
            v = (t >= O - tick_tol(t, P) && fabs(O + j * P - t) <= tick_tol(t, P)) ? 1.0 : 0.0;
        }
        inst->p[m->np + m->clock_tick[k]] = v;
    }
}

int fmugen_tick_round(fmugen_instance *inst, const double *u, int *changed, int *x_changed)
{
    const fmugen_model_def *m = inst->model;
    double next;
    int at = 0;
    *changed = *x_changed = 0;
    if (m->ns == 0) return fmugen_event_round(inst, u, changed, x_changed);
    int rc = fmugen_next_tick(inst, inst->s.time, &next, &at);
    if (rc != FMUGEN_OK) return rc;
    /* the same instant within the tick tolerance is the same tick (a step ending a rounding error away
     * from j period must not sample again) */
    double pmin = HUGE_VAL;
    const double *per = inst->ev_work + 5 * (size_t)m->nx + 3 * (size_t)m->nz + m->ng + m->na;
    for (int k = 0; k < m->ns; k++) pmin = fmin(pmin, per[k]);
    const int fresh = at && !(inst->s.tick_done &&
                              fabs(inst->s.tick_time - inst->s.time) <= tick_tol(inst->s.time, pmin));
    if (fresh) set_ticks(inst, inst->s.time, 1);
    rc = fmugen_event_round(inst, u, changed, x_changed);
    if (fresh) {
        set_ticks(inst, inst->s.time, 0);
        inst->s.tick_done = 1;
        inst->s.tick_time = inst->s.time;
        fmugen_invalidate(inst);
    }
    return rc;
}

int fmugen_tick_iteration(fmugen_instance *inst, const double *u, char *msg, size_t n)
{
    int changed, x_changed;
    int rc = fmugen_tick_round(inst, u, &changed, &x_changed);
    if (rc != FMUGEN_OK) {
        snprintf(msg, n, "the sampled update at t = %.17g failed: %s", inst->s.time, fmugen_model_status_text(rc));
        return rc;
    }
    return fmugen_event_iteration(inst, u, msg, n);
}
