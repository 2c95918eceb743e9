/* solver_common.c -- right-hand side with input extrapolation, Jacobian
 * (exact or finite differences), error norm and a dense LU solve used by the
 * Co-Simulation solvers. */
#include <float.h>
#include <math.h>
#include <string.h>
#include "solver.h"

void fmugen_inputs_at(const fmugen_instance *inst, double t0, const double *u0, double t, double *out)
{
    const int nu = inst->model->nu;
    const double dt = t - t0;
    for (int i = 0; i < nu; i++) out[i] = inst->du[i] != 0.0 ? u0[i] + inst->du[i] * dt : u0[i];
}

int fmugen_ode_rhs(fmugen_ode *ode, double t, const double *x, double *dx)
{
    fmugen_instance *inst = ode->inst;
    const fmugen_model_def *m = inst->model;
    fmugen_inputs_at(inst, ode->t0, ode->u0, t, ode->u_work);
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
        fmugen_inputs_at(inst, ode->t0, ode->u0, t, ode->u_work);
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
