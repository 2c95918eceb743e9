/* Hand-written test model for the fmugen runtime: a forced Van der Pol
 * oscillator with a mass, written against fmugen_model.h like generated code.
 *
 *   dx/dt = v
 *   m dv/dt = mu (1 - x^2) v - x + F        (solved with fmugen_spd_solve, 1x1)
 *   E = (m v^2 + x^2) / 2                   (output, no feedthrough)
 *   z = v + k F                             (output, direct feedthrough)
 *
 * m <= 0 makes the "mass matrix" [m] not positive definite: the model then
 * returns FMUGEN_NOT_POSITIVE_DEFINITE (tests the runtime's failure path).
 * x is a state and an output.  Compile with -DFMUGEN_TEST_NO_JACOBIAN for a
 * variant without Jacobian. */
#include "fmugen_model.h"

enum { MU, M, K };

static int evaluate(const double *p, double t, const double *x, const double *u, double *dx, double *y)
{
    (void)t;
    double H = p[M];
    double rhs = p[MU] * (1.0 - x[0] * x[0]) * x[1] - x[0] + u[0];
    int rc = fmugen_spd_solve(1, 1, &H, &rhs);
    if (rc != FMUGEN_OK) return rc;
    if (dx) {
        dx[0] = x[1];
        dx[1] = rhs;
    }
    if (y) {
        y[0] = 0.5 * (p[M] * x[1] * x[1] + x[0] * x[0]);
        y[1] = x[1] + p[K] * u[0];
    }
    return FMUGEN_OK;
}

#ifndef FMUGEN_TEST_NO_JACOBIAN
static int jacobian(const double *p, double t, const double *x, const double *u, double *dfdx, double *dfdu,
                    double *dgdx, double *dgdu)
{
    (void)t;
    (void)u;
    if (!(p[M] > 0)) return FMUGEN_NOT_POSITIVE_DEFINITE;
    const double im = 1.0 / p[M];
    if (dfdx) {
        dfdx[0] = 0.0;
        dfdx[1] = 1.0;
        dfdx[2] = (-2.0 * p[MU] * x[0] * x[1] - 1.0) * im;
        dfdx[3] = p[MU] * (1.0 - x[0] * x[0]) * im;
    }
    if (dfdu) {
        dfdu[0] = 0.0;
        dfdu[1] = im;
    }
    if (dgdx) {
        dgdx[0] = x[0];
        dgdx[1] = p[M] * x[1];
        dgdx[2] = 0.0;
        dgdx[3] = 1.0;
    }
    if (dgdu) {
        dgdu[0] = 0.0;
        dgdu[1] = p[K];
    }
    return FMUGEN_OK;
}
#endif

static const double x_start[] = {2.0, 0.0};
static const double x_nominal[] = {1.0, 1.0};
static const double u_start[] = {0.0};
static const double p_start[] = {1.0, 1.0, 0.5};
static const char *const x_names[] = {"x", "v"};
static const char *const u_names[] = {"F"};
static const char *const y_names[] = {"E", "z"};
static const char *const p_names[] = {"mu", "m", "k"};

const fmugen_model_def fmugen_model = {
    .model_identifier = "vdp",
    .guid = "{8c4e810f-3df3-4a00-8276-176fa3c9f000}",
    .nx = 2, .nu = 1, .ny = 2, .np = 3,
    .x_start = x_start, .x_nominal = x_nominal, .u_start = u_start, .p_start = p_start,
    .x_names = x_names, .u_names = u_names, .y_names = y_names, .p_names = p_names,
#ifdef FMUGEN_TEST_NO_JACOBIAN
    .has_jacobian = 0, .evaluate = evaluate, .jacobian = 0,
#else
    .has_jacobian = 1, .evaluate = evaluate, .jacobian = jacobian,
#endif
};
