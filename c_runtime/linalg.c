/* linalg.c -- the one linear solve generated models need: Cholesky of the
 * symmetric positive-definite mass matrix (the thesis solves H qdd = tau - b,
 * eqs. 40-42; a Cholesky factorisation uses the symmetry and reports when H
 * is not positive definite instead of dividing by a tiny pivot). */
#include <math.h>
#include "fmugen_model.h"

int fmugen_spd_solve(int n, int k, double *A, double *B)
{
    /* in-place Cholesky A = L L^T, L stored in the lower triangle */
    for (int j = 0; j < n; j++) {
        double d = A[j * n + j];
        for (int m = 0; m < j; m++) d -= A[j * n + m] * A[j * n + m];
        if (!(d > 0.0) || !isfinite(d)) return FMUGEN_NOT_POSITIVE_DEFINITE;
        d = sqrt(d);
        A[j * n + j] = d;
        for (int i = j + 1; i < n; i++) {
            double s = A[i * n + j];
            for (int m = 0; m < j; m++) s -= A[i * n + m] * A[j * n + m];
            A[i * n + j] = s / d;
        }
    }
    for (int c = 0; c < k; c++) {
        /* forward: L z = b */
        for (int i = 0; i < n; i++) {
            double s = B[i * k + c];
            for (int m = 0; m < i; m++) s -= A[i * n + m] * B[m * k + c];
            B[i * k + c] = s / A[i * n + i];
        }
        /* backward: L^T x = z */
        for (int i = n - 1; i >= 0; i--) {
            double s = B[i * k + c];
            for (int m = i + 1; m < n; m++) s -= A[m * n + i] * B[m * k + c];
            B[i * k + c] = s / A[i * n + i];
        }
    }
    return FMUGEN_OK;
}
