/*
 * batch.c -- the looped tree dynamics of c_runtime/chain_dynamics.c over many states in one call.
 *
 * Python (fmugen/batch/kernels.py) compiles this file once per machine into a shared library
 * and calls fmugen_batch() from several threads at once, each thread on its own range of states
 * with its own work array: the runtime keeps no state, so the results do not depend on how the
 * batch is split.  States are rows of row-major arrays (count x n); derivative blocks are
 * count x n x n.  The loop stops at the first state whose inputs are not finite or whose
 * dynamics fail, and reports its index: a batch of states usually comes from a sampler or an
 * optimiser, and one bad state there is a bug to be named, not a row to be skipped silently.
 */
#include <math.h>
#include <string.h>
#include "chain_dynamics.c"

/* what fmugen_batch computes (kind) */
#define BATCH_FD 0        /* qdd = FD(q, qd, tau) */
#define BATCH_FD_JAC 1    /* qdd, dqdd/dq, dqdd/dqd, M^-1 (= dqdd/dtau) */
#define BATCH_ID 2        /* tau = ID(q, qd, qdd) */
#define BATCH_ID_JAC 3    /* tau, dtau/dq, dtau/dqd, M (= dtau/dqdd) */
#define BATCH_M_COLUMNS 4 /* M(q), column j = ID(q, 0, e_j) without gravity: n calls of recursive Newton-Euler */
#define BATCH_M_JAC 5     /* M(q), the third block of the ID Jacobian at qd = qdd = 0 */
#define BATCH_MINV_COLUMNS 6 /* M(q)^-1, column j = FD(q, 0, e_j) without gravity: n calls of the ABA */
#define BATCH_MINV_JAC 7  /* M(q)^-1, the third block (dqdd/dtau) of the FD Jacobian at qd = tau = 0 */
#define BATCH_M_DIRECT 8  /* M(q) by composite rigid bodies (fmugen_chain_mass_matrix) */
#define BATCH_MINV_DIRECT 9 /* M(q)^-1 from the tree factorisation M = L^T L (fmugen_chain_mass_matrix_inverse) */

/* status beyond the runtime's FMUGEN_OK / FMUGEN_NOT_POSITIVE_DEFINITE / FMUGEN_NOT_FINITE */
#define BATCH_INPUT_NOT_FINITE 3
#define BATCH_UNKNOWN_KIND 4

/* doubles of work one thread needs for n bodies: the runtime's own (from its header, which may
 * grow) and the scratch of the blocks this file takes apart */
long fmugen_batch_work(int kind, int n)
{
    long nn = (long)n * n;
    switch (kind) {
    case BATCH_FD: case BATCH_ID: return FMUGEN_CHAIN_FD_WORK(n);
    case BATCH_FD_JAC: case BATCH_ID_JAC: return FMUGEN_CHAIN_WORK(n) + 3 * nn;
    case BATCH_M_COLUMNS: case BATCH_MINV_COLUMNS: return FMUGEN_CHAIN_FD_WORK(n) + 3L * n + FMUGEN_CHAIN_NG;
    case BATCH_M_JAC: case BATCH_MINV_JAC: return FMUGEN_CHAIN_WORK(n) + 3 * nn + 2L * n;
    case BATCH_M_DIRECT: return FMUGEN_CHAIN_FD_WORK(n);
    case BATCH_MINV_DIRECT: return FMUGEN_CHAIN_WORK(n);
    default: return -1;
    }
}

static int finite_row(const double *x, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(x[i])) return 0;
    return 1;
}

/* the three n x n blocks of a row-major n x 3n Jacobian J into a, b, c */
static void split3(int n, const double *J, double *a, double *b, double *c)
{
    for (int r = 0; r < n; r++) {
        const double *row = J + (long)r * 3 * n;
        memcpy(a + (long)r * n, row, sizeof(double) * n);
        memcpy(b + (long)r * n, row + n, sizeof(double) * n);
        memcpy(c + (long)r * n, row + 2 * n, sizeof(double) * n);
    }
}

/* Columns of M (fd = 0: tau = ID(q, 0, e_j)) or of M^-1 (fd = 1: qdd = FD(q, 0, e_j)) with gravity
 * off, so that the velocity and gravity terms vanish and the result is the matrix times e_j;
 * damping and friction vanish at qd = 0.  out is row-major n x n. */
static int columns(int fd, int n, const int *jt, const double *lc, const double *g, const double *q,
                   double *out, double *work)
{
    double *zero = work + FMUGEN_CHAIN_FD_WORK(n), *e = zero + n, *col = e + n, *g0 = col + n;
    memset(zero, 0, sizeof(double) * 2 * n);
    memcpy(g0, g, sizeof(double) * FMUGEN_CHAIN_NG);
    g0[0] = g0[1] = g0[2] = 0.0;
    for (int j = 0; j < n; j++) {
        e[j] = 1.0;
        int s = fd ? fmugen_chain_fd(n, jt, lc, g0, q, zero, e, 0, NULL, NULL, col, NULL, work)
                   : fmugen_chain_id(n, jt, lc, g0, q, zero, e, 0, NULL, NULL, col, work);
        e[j] = 0.0;
        if (s != FMUGEN_OK) return s;
        for (int r = 0; r < n; r++) out[(long)r * n + j] = col[r];
    }
    return FMUGEN_OK;
}

/* kind (above) for states [0, count) of a, b, c (count x n each; b, c unused by the mass matrix);
 * outputs out0 (count x n; the mass matrix: count x n x n) and, for the Jacobians, out1..out3
 * (count x n x n).  Returns FMUGEN_OK, or the status of the first bad state and its index in *bad. */
int fmugen_batch(int kind, int n, const int *jt, const double *lc, const double *g, long count,
                 const double *a, const double *b, const double *c,
                 double *out0, double *out1, double *out2, double *out3, double *work, long *bad)
{
    long nn = (long)n * n;
    *bad = -1;
    if (fmugen_batch_work(kind, n) < 0) return BATCH_UNKNOWN_KIND;
    for (long k = 0; k < count; k++) {
        const double *q = a + k * n, *qd = b ? b + k * n : NULL, *x = c ? c + k * n : NULL;
        int s;
        if (!finite_row(q, n) || (qd && !finite_row(qd, n)) || (x && !finite_row(x, n))) {
            *bad = k;
            return BATCH_INPUT_NOT_FINITE;
        }
        switch (kind) {
        case BATCH_FD:
            s = fmugen_chain_fd(n, jt, lc, g, q, qd, x, 0, NULL, NULL, out0 + k * n, NULL, work);
            break;
        case BATCH_ID:
            s = fmugen_chain_id(n, jt, lc, g, q, qd, x, 0, NULL, NULL, out0 + k * n, work);
            break;
        case BATCH_FD_JAC: {
            double *J = work + FMUGEN_CHAIN_WORK(n);
            s = fmugen_chain_fd_jacobian(n, jt, lc, g, q, qd, x, 0, NULL, NULL, out0 + k * n, J, NULL, work);
            if (s == FMUGEN_OK) split3(n, J, out1 + k * nn, out2 + k * nn, out3 + k * nn);
            break;
        }
        case BATCH_ID_JAC: {
            double *J = work + FMUGEN_CHAIN_WORK(n);
            s = fmugen_chain_id_jacobian(n, jt, lc, g, q, qd, x, 0, NULL, NULL, out0 + k * n, J, work);
            if (s == FMUGEN_OK) split3(n, J, out1 + k * nn, out2 + k * nn, out3 + k * nn);
            break;
        }
        case BATCH_M_JAC: case BATCH_MINV_JAC: {
            double *J = work + FMUGEN_CHAIN_WORK(n), *zero = J + 3 * nn, *res = zero + n;
            memset(zero, 0, sizeof(double) * n);
            s = kind == BATCH_M_JAC
                ? fmugen_chain_id_jacobian(n, jt, lc, g, q, zero, zero, 0, NULL, NULL, res, J, work)
                : fmugen_chain_fd_jacobian(n, jt, lc, g, q, zero, zero, 0, NULL, NULL, res, J, NULL, work);
            if (s == FMUGEN_OK)
                for (int r = 0; r < n; r++) memcpy(out0 + k * nn + (long)r * n, J + (long)r * 3 * n + 2 * n,
                                                   sizeof(double) * n);
            break;
        }
        case BATCH_M_DIRECT:
            s = fmugen_chain_mass_matrix(n, jt, lc, g, q, out0 + k * nn, work);
            break;
        case BATCH_MINV_DIRECT:
            s = fmugen_chain_mass_matrix_inverse(n, jt, lc, g, q, out0 + k * nn, work);
            break;
        case BATCH_M_COLUMNS: case BATCH_MINV_COLUMNS:
            s = columns(kind == BATCH_MINV_COLUMNS, n, jt, lc, g, q, out0 + k * nn, work);
            break;
        default:
            s = BATCH_UNKNOWN_KIND;
        }
        if (s != FMUGEN_OK) {
            *bad = k;
            return s;
        }
    }
    return FMUGEN_OK;
}
