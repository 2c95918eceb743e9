/*
 * solver.h -- the common interface of the Co-Simulation solvers.
 *
 * A solver advances the instance's state x from inst->s.time to t_end for
 *     dx/dt = f(t, x, u(t), p),   u(t) = u0 + du (t - t0),
 * (inputs held constant over a communication step, or extrapolated linearly
 * when fmi2SetRealInputDerivatives gave du; for FMI 3.0, set by the importer
 * in the intermediate update: fmugen_ode_inputs).  It changes inst->s.time and
 * inst->x only on accepted steps, so after a failure they hold the last good
 * point.  It returns FMUGEN_SOLVER_OK or a failure code and writes the reason
 * into msg.
 */
#ifndef FMUGEN_SOLVER_H
#define FMUGEN_SOLVER_H

#include "fmugen_runtime.h"

#define FMUGEN_SOLVER_OK 0
#define FMUGEN_SOLVER_FAILED 1
/* stopped at a located state event: inst->s.time and inst->x are the point
 * just after the crossing; fmi2DoStep runs the event iteration and goes on */
#define FMUGEN_SOLVER_EVENT 2

/* stopped after an accepted internal step because the importer asked for an early return in FMI 3.0's
 * intermediate update (fmugen_cs_ext): inst->s.time and inst->x are that step's end */
#define FMUGEN_SOLVER_EARLY 3

/* internal steps allowed in one communication step */
#define FMUGEN_SOLVER_MAX_STEPS 100000

typedef struct fmugen_ode {
    fmugen_instance *inst;
    double t0;          /* communication point the inputs refer to */
    const double *u0;   /* nu: inputs at t0 */
    double *u_work;     /* nu: u(t) */
    int model_code;     /* FMUGEN_* code of the last failed model call */
} fmugen_ode;

/* u(t) = u0 + du (t - t0) into out (nu) */
FMUGEN_INTERNAL void fmugen_inputs_at(const fmugen_instance *inst, double t0, const double *u0, double t,
                                      double *out);
/* u(t) into out (nu), for the right-hand side, the Jacobian, event indicators and the step's end: the
 * polynomial of fmugen_inputs_at, or, for an FMI 3.0 instance whose importer sets its inputs in the
 * intermediate update, the values it sets for t (fmugen_cs_ext.inputs_at).  Always the polynomial for FMI
 * 2.0 (no cs_ext), so those steps are what they were before this existed. */
static inline void fmugen_ode_inputs(fmugen_ode *ode, double t, double *out)
{
    const fmugen_cs_ext *e = ode->inst->cs_ext;
    if (e != NULL && e->inputs_at != NULL) e->inputs_at(ode, t, out);
    else fmugen_inputs_at(ode->inst, ode->t0, ode->u0, t, out);
}
/* dx = f(t, x, u(t), p); counts n_rhs.  Returns FMUGEN_OK, a model error or
 * FMUGEN_NOT_FINITE. */
FMUGEN_INTERNAL int fmugen_ode_rhs(fmugen_ode *ode, double t, const double *x, double *dx);
/* J = df/dx (nx*nx row-major) at (t, x) with fx = f(t, x): the model's exact
 * Jacobian when it has one, else forward differences (tmp: 2*nx doubles).
 * Counts n_jac. */
FMUGEN_INTERNAL int fmugen_ode_jacobian(fmugen_ode *ode, double t, const double *x, const double *fx,
                                        double *J, double *tmp);
/* Weighted RMS norm sqrt(1/n sum (e_i / sk_i)^2),
 * sk_i = atol x_nominal_i + rtol max(|a_i|, |b_i|). */
FMUGEN_INTERNAL double fmugen_error_norm(const fmugen_instance *inst, const double *e, const double *a,
                                         const double *b);
/* LU factorisation with partial pivoting of A (n x n, row-major), in place.
 * Returns 0, or 1 when a pivot is zero or not finite. */
FMUGEN_INTERNAL int fmugen_lu_factor(int n, double *A, int *ipiv);
FMUGEN_INTERNAL void fmugen_lu_solve(int n, const double *LU, const int *ipiv, double *b);

/* After a communication step that the solver completed (inst->s.time is the
 * end point): states finite; derivatives and outputs at the end point finite
 * (one cached model evaluation, which the importer's fmi2GetReal reuses); and
 * states, inputs and outputs inside the model's validity ranges
 * (fmugen_model_def.x_min ...).  Returns fmi2OK, fmi2Warning (a value left
 * its range; logged) or fmi2Discard (reason in msg). */
FMUGEN_INTERNAL fmi2Status fmugen_check_step_result(fmugen_instance *inst, const char *fn, char *msg, size_t n);
/* The validity-range part of it alone, at the current point (y_cache must be
 * valid): fmi2OK, fmi2Warning (logged) or fmi2Discard (range_check = 2; the
 * reason in msg, not logged). */
FMUGEN_INTERNAL fmi2Status fmugen_check_ranges(fmugen_instance *inst, const char *fn, char *msg, size_t n);

/* After an accepted internal step from (t0, x0, f0) to (t1, x1, f1) of a
 * model with event indicators (events.c; f1 NULL: computed when needed):
 * 0 when no indicator changed its domain (zpre takes the values at t1); 1
 * when one did: the crossing is located on the step's interpolant (r5 NULL:
 * cubic Hermite; else Dormand-Prince's continuous extension, r5 = h sum d_i
 * k_i), inst->x and inst->s.time are the point just after it; -1 when the
 * indicators could not be evaluated (reason in msg). */
FMUGEN_INTERNAL int fmugen_step_event(fmugen_ode *ode, double t0, const double *x0, const double *f0, double t1,
                                      const double *x1, const double *f1, const double *r5, char *msg, size_t n);

/* Every solver calls this after each accepted internal step, when inst->s.time, inst->x and its step-size
 * memory are that step's end: FMI 3.0's intermediate update (fmugen_cs_ext.step_accepted).  1: return
 * FMUGEN_SOLVER_EARLY now.  Always 0 for FMI 2.0 (no cs_ext), so the step is what it was without it. */
static inline int fmugen_step_accepted(fmugen_ode *ode)
{
    const fmugen_cs_ext *e = ode->inst->cs_ext;
    return e != NULL && e->step_accepted != NULL && e->step_accepted(ode);
}

FMUGEN_INTERNAL int fmugen_solve_dopri5(fmugen_ode *ode, double t_end, char *msg, size_t n);
FMUGEN_INTERNAL int fmugen_solve_rodas3(fmugen_ode *ode, double t_end, char *msg, size_t n);
FMUGEN_INTERNAL int fmugen_solve_rk4(fmugen_ode *ode, double t_end, char *msg, size_t n);

#endif
