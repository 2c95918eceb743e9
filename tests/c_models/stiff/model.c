/* Hand-written stiff test model for the fmugen runtime: a slow first-order
 * lag driven by a fast one,
 *
 *   dy_slow/dt = -a y_slow + y_fast
 *   dy_fast/dt = -L (y_fast - w)
 *   s = y_slow + y_fast                     (output)
 *
 * eigenvalues -a and -L (defaults 1 and 1e5 1/s: stiffness ratio 1e5).
 * Classical RK4 is stable only for h L <= 2.785.  Compile with
 * -DFMUGEN_TEST_NO_JACOBIAN for a variant without Jacobian. */
#include "fmugen_model.h"

enum { A, L };

static int evaluate(const double *p, double t, const double *x, const double *u, double *dx, double *y)
{
    (void)t;
    if (dx) {
        dx[0] = -p[A] * x[0] + x[1];
        dx[1] = -p[L] * (x[1] - u[0]);
    }
    if (y) y[0] = x[0] + x[1];
    return FMUGEN_OK;
}

#ifndef FMUGEN_TEST_NO_JACOBIAN
static int jacobian(const double *p, double t, const double *x, const double *u, double *dfdx, double *dfdu,
                    double *dgdx, double *dgdu)
{
    (void)t;
    (void)x;
    (void)u;
    if (dfdx) {
        dfdx[0] = -p[A];
        dfdx[1] = 1.0;
        dfdx[2] = 0.0;
        dfdx[3] = -p[L];
    }
    if (dfdu) {
        dfdu[0] = 0.0;
        dfdu[1] = p[L];
    }
    if (dgdx) {
        dgdx[0] = 1.0;
        dgdx[1] = 1.0;
    }
    if (dgdu) dgdu[0] = 0.0;
    return FMUGEN_OK;
}
#endif

static const double x_start[] = {0.0, 0.0};
static const double x_nominal[] = {1.0, 1.0};
static const double u_start[] = {1.0};
static const double p_start[] = {1.0, 1e5};
static const char *const x_names[] = {"y_slow", "y_fast"};
static const char *const u_names[] = {"w"};
static const char *const y_names[] = {"s"};
static const char *const p_names[] = {"a", "L"};

const fmugen_model_def fmugen_model = {
    .model_identifier = "stiff",
    .guid = "{5b0c2f4e-9d61-4f7a-a1c3-0e2d7b9f1a00}",
    .nx = 2, .nu = 1, .ny = 1, .np = 2,
    .x_start = x_start, .x_nominal = x_nominal, .u_start = u_start, .p_start = p_start,
    .x_names = x_names, .u_names = u_names, .y_names = y_names, .p_names = p_names,
#ifdef FMUGEN_TEST_NO_JACOBIAN
    .has_jacobian = 0, .evaluate = evaluate, .jacobian = 0,
#else
    .has_jacobian = 1, .evaluate = evaluate, .jacobian = jacobian,
#endif
};
