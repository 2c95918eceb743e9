/* chain_dynamics.c -- looped dynamics of a kinematic tree or serial chain (see chain_dynamics.h).
 *
 * Spatial vectors (Featherstone) in base coordinates, 6 doubles:
 *   motion m = [omega; v_O]  (v_O: velocity of the body point at the base origin)
 *   force  f = [n_O; f]      (n_O: moment about the base origin)
 *   m x y  = [w x wy ; w x vy + v x wy]       (crm)
 *   m x* f = [w x n + v x f ; w x f]           (crf)
 * Spatial inertia of a link at the base origin (h = m c, c its COM):
 *   I = [[I_c + m (c.c 1 - c c^T), [h]x], [[h]x^T, m 1]]
 * Gravity enters as the base acceleration a_0 = [0; -g].
 *
 * Why world coordinates: the articulated-body inertias of the ABA add up
 * without the 6x6 congruence transform of every link step, and in the
 * derivatives of Newton-Euler (Carpentier & Mansard, RSS 2018) a change of
 * q_j rotates the whole subtree about S_j, so every derivative is one
 * cross product away from a composite sum (the derivation is in
 * c_runtime/README.md, "Looped chain dynamics").
 */
#if defined(__GNUC__) && !defined(__clang__)
/* the O(n^2) loops below are axpy over contiguous rows: let gcc vectorise
 * them whatever -O level the FMU is built with (the rest of the runtime
 * keeps the build's flags) */
#pragma GCC optimize("O3")
#endif
#include <math.h>
#include <string.h>
#include "chain_dynamics.h"

static void cross3(const double *a, const double *b, double *o)
{
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}

static double dot6(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5];
}

/* o = m x y (motion cross motion) */
static void crm(const double *m, const double *y, double *o)
{
    double t[3];
    cross3(m, y, o);
    cross3(m, y + 3, o + 3);
    cross3(m + 3, y, t);
    o[3] += t[0]; o[4] += t[1]; o[5] += t[2];
}

/* o = m x* f (motion cross force) */
static void crf(const double *m, const double *f, double *o)
{
    double t[3];
    cross3(m, f, o);
    cross3(m + 3, f + 3, t);
    o[0] += t[0]; o[1] += t[1]; o[2] += t[2];
    cross3(m, f + 3, o + 3);
}

/* o = A x (A 6x6 row-major) */
static void mv6(const double *A, const double *x, double *o)
{
    for (int r = 0; r < 6; r++) o[r] = dot6(A + 6 * r, x);
}

static const double ZERO6[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};

/* A rigid body's spatial inertia at the base origin in its ten numbers (sums of them -- the
 * composite inertias -- stay of that form): m, h = m c (3), J = I_c + m (c.c 1 - c c^T) about
 * the origin (xx yy zz xy xz yz).  Applied as [J w + h x v_O ; m v_O - h x w]: 24 products
 * where the 6x6 matrix takes 36, and a sum takes 10 additions, not 36. */
#define SI_N 10
static void si_apply(const double *I, const double *x, double *o)
{
    const double m = I[0], *h = I + 1, *J = I + 4, *w = x, *vo = x + 3;
    o[0] = J[0] * w[0] + J[3] * w[1] + J[4] * w[2] + (h[1] * vo[2] - h[2] * vo[1]);
    o[1] = J[3] * w[0] + J[1] * w[1] + J[5] * w[2] + (h[2] * vo[0] - h[0] * vo[2]);
    o[2] = J[4] * w[0] + J[5] * w[1] + J[2] * w[2] + (h[0] * vo[1] - h[1] * vo[0]);
    o[3] = m * vo[0] - (h[1] * w[2] - h[2] * w[1]);
    o[4] = m * vo[1] - (h[2] * w[0] - h[0] * w[2]);
    o[5] = m * vo[2] - (h[0] * w[1] - h[1] * w[0]);
}

/* the 6x6 matrix (row-major) of a ten-number spatial inertia: [[J, [h]x], [[h]x^T, m 1]] */
static void si_expand(const double *I, double *A)
{
    const double m = I[0], *h = I + 1, *J = I + 4;
    const double Jm[9] = {J[0], J[3], J[4], J[3], J[1], J[5], J[4], J[5], J[2]};
    const double hx[9] = {0.0, -h[2], h[1], h[2], 0.0, -h[0], -h[1], h[0], 0.0};
    for (int r = 0; r < 3; r++)
        for (int k = 0; k < 3; k++) {
            A[6 * r + k] = Jm[3 * r + k];
            A[6 * r + k + 3] = hx[3 * r + k];
            A[6 * (k + 3) + r] = hx[3 * r + k];
            A[6 * (r + 3) + k + 3] = r == k ? m : 0.0;
        }
}

/* the joint's passive force b qd + F_c tanh(qd / v_c) (damping, smooth Coulomb friction); *slope
 * receives its derivative by qd */
static double joint_friction(const double *L, double qd, double *slope)
{
    double b = L[FMUGEN_CHAIN_DAMPING], fc = L[FMUGEN_CHAIN_FRICTION], f = b * qd;
    double s = b;
    if (fc != 0.0) {
        double vc = L[FMUGEN_CHAIN_FRICTION_VELOCITY], t = tanh(qd / vc);
        f += fc * t;
        s += fc * (1.0 - t * t) / vc;
    }
    if (slope) *slope = s;
    return f;
}

/* o = A B (3x3, row-major) */
static void mul33(const double *A, const double *B, double *o)
{
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
            o[3 * r + c] = A[3 * r] * B[c] + A[3 * r + 1] * B[3 + c] + A[3 * r + 2] * B[6 + c];
}

/* World pose of every body frame, motion subspaces S_i, body inertias at the
 * base origin (SI_N numbers each, see si_apply; when I is not NULL) and the end-effector position. */
static void kinematics(int n, const int *jt, const double *lc, const double *g, const double *q,
                       double *R, double *p, double *S, double *I, double *p_ee)
{
    static const double R0[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, p0[3] = {0, 0, 0};
    for (int i = 0; i < n; i++) {
        const double *L = lc + FMUGEN_CHAIN_NC * i, *k = L + FMUGEN_CHAIN_AXIS, *pl = L + FMUGEN_CHAIN_POS;
        int par = jt[n + i];
        const double *Rp = par >= 0 ? R + 9 * par : R0, *pp = par >= 0 ? p + 3 * par : p0;
        double *Ri = R + 9 * i, *pi = p + 3 * i, Rq[9], z[3];
        mul33(Rp, L + FMUGEN_CHAIN_ROT, Rq); /* the placed frame F_parent P_i */
        for (int r = 0; r < 3; r++) {
            pi[r] = pp[r] + Rp[3 * r] * pl[0] + Rp[3 * r + 1] * pl[1] + Rp[3 * r + 2] * pl[2];
            z[r] = Rq[3 * r] * k[0] + Rq[3 * r + 1] * k[1] + Rq[3 * r + 2] * k[2]; /* world axis */
        }
        double *Si = S + 6 * i;
        if (jt[i]) {
            /* R_i = Rq Rot(k, q): Rodrigues, c 1 + s [k]x + (1 - c) k k^T; the z axis
             * (every DH joint) without the products by zero */
            double c = cos(q[i]), s = sin(q[i]);
            if (k[0] == 0.0 && k[1] == 0.0 && k[2] == 1.0) {
                for (int r = 0; r < 3; r++) {
                    double x = Rq[3 * r], y = Rq[3 * r + 1];
                    Ri[3 * r] = c * x + s * y;
                    Ri[3 * r + 1] = c * y - s * x;
                    Ri[3 * r + 2] = Rq[3 * r + 2];
                }
            } else {
                double t = 1.0 - c;
                double J[9] = {c + t * k[0] * k[0], t * k[0] * k[1] - s * k[2], t * k[0] * k[2] + s * k[1],
                               t * k[0] * k[1] + s * k[2], c + t * k[1] * k[1], t * k[1] * k[2] - s * k[0],
                               t * k[0] * k[2] - s * k[1], t * k[1] * k[2] + s * k[0], c + t * k[2] * k[2]};
                mul33(Rq, J, Ri);
            }
            /* S: rotation about z through p_i */
            Si[0] = z[0]; Si[1] = z[1]; Si[2] = z[2];
            cross3(pi, z, Si + 3);
        } else {
            memcpy(Ri, Rq, sizeof Rq);
            for (int r = 0; r < 3; r++) pi[r] += z[r] * q[i];
            Si[0] = Si[1] = Si[2] = 0.0;
            Si[3] = z[0]; Si[4] = z[1]; Si[5] = z[2];
        }
        /* inertia: COM c = p + R c_i, I_c rotated R I R^T, moved to the origin */
        if (I) {
            double m = L[FMUGEN_CHAIN_MASS];
            const double *cl = L + FMUGEN_CHAIN_COM, *J = L + FMUGEN_CHAIN_INERTIA;
            double Jl[9] = {J[0], J[3], J[4], J[3], J[1], J[5], J[4], J[5], J[2]};
            double c[3], RJ[9], Jw[9];
            for (int r = 0; r < 3; r++)
                c[r] = pi[r] + Ri[3 * r] * cl[0] + Ri[3 * r + 1] * cl[1] + Ri[3 * r + 2] * cl[2];
            mul33(Ri, Jl, RJ);
            for (int r = 0; r < 3; r++)
                for (int kk = r; kk < 3; kk++)
                    Jw[3 * r + kk] = Jw[3 * kk + r] =
                        RJ[3 * r] * Ri[3 * kk] + RJ[3 * r + 1] * Ri[3 * kk + 1] + RJ[3 * r + 2] * Ri[3 * kk + 2];
            double cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
            double *Ii = I + SI_N * i;
            Ii[0] = m;
            Ii[1] = m * c[0]; Ii[2] = m * c[1]; Ii[3] = m * c[2];
            Ii[4] = Jw[0] + m * (cc - c[0] * c[0]);
            Ii[5] = Jw[4] + m * (cc - c[1] * c[1]);
            Ii[6] = Jw[8] + m * (cc - c[2] * c[2]);
            Ii[7] = Jw[1] - m * c[0] * c[1];
            Ii[8] = Jw[2] - m * c[0] * c[2];
            Ii[9] = Jw[5] - m * c[1] * c[2];
        }
    }
    if (p_ee) {
        int eb = jt[2 * n];
        for (int r = 0; r < 3; r++)
            p_ee[r] = eb < 0 ? 0.0
                             : p[3 * eb + r] + R[9 * eb + 3 * r] * g[3] + R[9 * eb + 3 * r + 1] * g[4]
                                   + R[9 * eb + 3 * r + 2] * g[5];
    }
}

/* The articulated-body algorithm on world quantities already computed:
 * S (6n), I (SI_N n: the body inertias); IA (36n) receives the articulated
 * inertias (6x6); scratch v, c, pA, U, acc (6n each), D, u (n each).  Bodies
 * are numbered parents first, so one sweep up and one down visit a tree. */
static int aba(int n, const int *jt, const double *lc, const double *g, const double *qd, const double *tau,
               const double *fx, const double *S, const double *I, double *IA, double *v, double *c, double *pA,
               double *U, double *D, double *u, double *acc, double *qdd)
{
    /* pass 1: velocities, velocity-product accelerations c_i = v_i x S_i qd_i, bias forces */
    for (int i = 0; i < n; i++) {
        int par = jt[n + i];
        const double *vp = par >= 0 ? v + 6 * par : ZERO6, *Si = S + 6 * i;
        double *vi = v + 6 * i, h[6];
        for (int k = 0; k < 6; k++) vi[k] = vp[k] + Si[k] * qd[i];
        crm(vi, Si, c + 6 * i);
        for (int k = 0; k < 6; k++) c[6 * i + k] *= qd[i];
        si_apply(I + SI_N * i, vi, h);
        si_expand(I + SI_N * i, IA + 36 * i);
        crf(vi, h, pA + 6 * i);
        if (fx)
            for (int k = 0; k < 6; k++) pA[6 * i + k] -= fx[6 * i + k];
    }
    /* pass 2: articulated inertias and bias forces, leaves to base */
    for (int i = n - 1; i >= 0; i--) {
        const double *L = lc + FMUGEN_CHAIN_NC * i, *Si = S + 6 * i;
        double *Ii = IA + 36 * i, *Ui = U + 6 * i, *pi = pA + 6 * i;
        int par = jt[n + i];
        mv6(Ii, Si, Ui);
        D[i] = dot6(Si, Ui) + L[FMUGEN_CHAIN_ROTOR];
        if (!(D[i] > 0.0) || !isfinite(D[i])) return FMUGEN_NOT_POSITIVE_DEFINITE;
        u[i] = tau[i] - joint_friction(L, qd[i], NULL) - dot6(Si, pi);
        if (par >= 0) {
            double *Ip = IA + 36 * par, *pp = pA + 6 * par, Ic[6], Ud[6];
            double inv = 1.0 / D[i], uD = u[i] * inv;
            for (int k = 0; k < 6; k++) Ud[k] = Ui[k] * inv;
            for (int r = 0; r < 6; r++)
                for (int k = 0; k < 6; k++) Ii[6 * r + k] -= Ud[r] * Ui[k];
            mv6(Ii, c + 6 * i, Ic);
            for (int k = 0; k < 36; k++) Ip[k] += Ii[k];
            for (int k = 0; k < 6; k++) pp[k] += pi[k] + Ic[k] + Ui[k] * uD;
        }
    }
    /* pass 3: accelerations, base to leaves */
    const double a0[6] = {0.0, 0.0, 0.0, -g[0], -g[1], -g[2]};
    for (int i = 0; i < n; i++) {
        int par = jt[n + i];
        const double *Si = S + 6 * i, *ap = par >= 0 ? acc + 6 * par : a0;
        double *a = acc + 6 * i;
        for (int k = 0; k < 6; k++) a[k] = ap[k] + c[6 * i + k];
        qdd[i] = (u[i] - dot6(U + 6 * i, a)) / D[i];
        for (int k = 0; k < 6; k++) a[k] += Si[k] * qdd[i];
    }
    for (int i = 0; i < n; i++)
        if (!isfinite(qdd[i])) return FMUGEN_NOT_FINITE;
    return FMUGEN_OK;
}

/* External wrenches as world spatial forces at the base origin, fx (6n):
 * [t + c x f; f] on body ext_link[e] (force f at its centre of mass c,
 * torque t, base coordinates); per body also c, f, t (9n: the derivatives
 * need them).  Returns fx, or NULL when there are none. */
static double *external_forces(int n, int ne, const int *ext_link, const double *ext, const double *lc,
                               const double *R, const double *p, double *fx, double *cft)
{
    if (ne <= 0) return NULL;
    memset(fx, 0, (size_t)6 * n * sizeof(double));
    memset(cft, 0, (size_t)9 * n * sizeof(double));
    for (int e = 0; e < ne; e++) {
        int k = ext_link[e];
        const double *Rk = R + 9 * k, *cl = lc + FMUGEN_CHAIN_NC * k + FMUGEN_CHAIN_COM, *f = ext + 6 * e;
        double *c = cft + 9 * k, m[3];
        for (int r = 0; r < 3; r++)
            c[r] = p[3 * k + r] + Rk[3 * r] * cl[0] + Rk[3 * r + 1] * cl[1] + Rk[3 * r + 2] * cl[2];
        for (int r = 0; r < 3; r++) {
            c[3 + r] += f[r];
            c[6 + r] += f[3 + r];
        }
        cross3(c, f, m);
        for (int r = 0; r < 3; r++) {
            fx[6 * k + r] += f[3 + r] + m[r];
            fx[6 * k + 3 + r] += f[r];
        }
    }
    return fx;
}

int fmugen_chain_fd(int n, const int *jt, const double *lc, const double *g, const double *q,
                    const double *qd, const double *tau, int ne, const int *ext_link, const double *ext,
                    double *qdd, double *p_ee, double *work)
{
    double *R = work, *p = R + 9 * n, *S = p + 3 * n, *IA = S + 6 * n, *v = IA + 36 * n;
    double *c = v + 6 * n, *pA = c + 6 * n, *U = pA + 6 * n, *D = U + 6 * n, *u = D + n;
    double *fx = u + n, *cft = fx + 6 * n, *acc = cft + 9 * n, *I = acc + 6 * n;
    kinematics(n, jt, lc, g, q, R, p, S, I, p_ee);
    const double *f = external_forces(n, ne, ext_link, ext, lc, R, p, fx, cft);
    return aba(n, jt, lc, g, qd, tau, f, S, I, IA, v, c, pA, U, D, u, acc, qdd);
}

/* K -= A + A^T with A = I crm(v): the velocity term of d(I a + v x* I v),
 * summed over a subtree (symmetric).  With I = [[J, H], [H^T, m 1]],
 * H = [h]x, crm(v) = [[W, 0], [V, W]] (W = [w]x, V = [v_O]x):
 *   A = [[J W + H V, H W], [H^T W + m V, m W]]
 * and each product X W (X 3x3) is one cross product per row: row_r(X W) = x_r x w. */
static void add_K(double *K, const double *I, const double *vel)
{
    const double *w = vel, *vo = vel + 3, *hv = I + 1, *Jv = I + 4;
    const double Jm[9] = {Jv[0], Jv[3], Jv[4], Jv[3], Jv[1], Jv[5], Jv[4], Jv[5], Jv[2]};
    const double Hm[9] = {0.0, -hv[2], hv[1], hv[2], 0.0, -hv[0], -hv[1], hv[0], 0.0};
    double A[36];
    for (int r = 0; r < 3; r++) {
        const double *J = Jm + 3 * r, *H = Hm + 3 * r;
        double Ht[3] = {-H[0], -H[1], -H[2]}; /* rows of [h]x^T = -[h]x */
        double a[3], b[3];
        cross3(J, w, a);
        cross3(H, vo, b);
        A[6 * r] = a[0] + b[0]; A[6 * r + 1] = a[1] + b[1]; A[6 * r + 2] = a[2] + b[2];
        cross3(H, w, a);
        A[6 * r + 3] = a[0]; A[6 * r + 4] = a[1]; A[6 * r + 5] = a[2];
        cross3(Ht, w, a);
        A[6 * (r + 3)] = a[0]; A[6 * (r + 3) + 1] = a[1]; A[6 * (r + 3) + 2] = a[2];
    }
    double m = I[0];
    /* m V and m W: rows of m [x]x */
    double mV[9] = {0.0, -vo[2], vo[1], vo[2], 0.0, -vo[0], -vo[1], vo[0], 0.0};
    double mW[9] = {0.0, -w[2], w[1], w[2], 0.0, -w[0], -w[1], w[0], 0.0};
    for (int r = 0; r < 3; r++)
        for (int k = 0; k < 3; k++) {
            A[6 * (r + 3) + k] += m * mV[3 * r + k];
            A[6 * (r + 3) + k + 3] = m * mW[3 * r + k];
        }
    for (int r = 0; r < 6; r++)
        for (int k = r; k < 6; k++) {
            double t = A[6 * r + k] + A[6 * k + r];
            K[6 * r + k] -= t;
            if (k != r) K[6 * k + r] -= t;
        }
}

/* M^-1 of a tree from the factorisation M = L^T L without fill-in (Featherstone, "Efficient
 * factorization of the joint-space inertia matrix for branched kinematic trees", IJRR 2005):
 * with bodies numbered parents first, L[i][j] is nonzero only for the joints j on the path from
 * i to the base, and so is X = L^-1; then M^-1 = X X^T, M^-1[a][b] = sum over the joints k on
 * both paths of X[a][k] X[b][k].  Costs: sum d_i^2 / 2 for L and for X, nb per joint on a path
 * for the product (d_i the depth of i, nb its block's size), against nb^3 / 2 for a dense
 * Cholesky factor and inverse.  M (n x n, the entries M[i][j] of j on i's path) is overwritten
 * by L; X^T is kept block by block like M^-1 (Mb): row k at Xb + off[k], entry b - lo[k] =
 * X[b][k]; both blocks' rows are full (nb entries, the zeros written). */
static int tree_minv(int n, const int *jt, double *M, const int *lo, const int *hi, const int *off, double *Xb,
                     double *Mb, int *end)
{
    for (int k = n - 1; k >= 0; k--) { /* L^T L: leaves first */
        double d = M[(size_t)k * n + k];
        if (!(d > 0.0) || !isfinite(d)) return FMUGEN_NOT_POSITIVE_DEFINITE;
        d = sqrt(d);
        M[(size_t)k * n + k] = d;
        for (int i = jt[n + k]; i >= 0; i = jt[n + i]) M[(size_t)k * n + i] /= d;
        for (int i = jt[n + k]; i >= 0; i = jt[n + i]) {
            double lki = M[(size_t)k * n + i];
            for (int j = i; j >= 0; j = jt[n + j]) M[(size_t)i * n + j] -= lki * M[(size_t)k * n + j];
        }
    }
    for (int i = 0; i < n; i++) { /* the rows of every block of X^T, then X = L^-1 row by row */
        if (lo[i] == i) memset(Xb + off[i], 0, (size_t)(hi[i] - i) * (hi[i] - i) * sizeof(double));
    }
    for (int i = 0; i < n; i++) {
        const double *Li = M + (size_t)i * n;
        double inv = 1.0 / Li[i];
        int l = lo[i];
        Xb[off[i] + i - l] = inv;
        /* X[i][k] = -(sum over j on the path from lambda(i) up to k of L[i][j] X[j][k]) / L[i][i] */
        for (int k = jt[n + i]; k >= 0; k = jt[n + k]) {
            double s = 0.0;
            for (int j = jt[n + i];; j = jt[n + j]) {
                s += Li[j] * Xb[off[k] + j - l];
                if (j == k) break;
            }
            Xb[off[k] + i - l] = -s * inv;
        }
    }
    /* X[b][k] is nonzero only for b in the subtree of k, whose indices lie in [k, end[k]) (numbered
     * parents first; a subtree need not be contiguous, but the others' entries there are zeros) */
    for (int k = 0; k < n; k++) end[k] = k + 1;
    for (int k = n - 1; k >= 0; k--)
        if (jt[n + k] >= 0 && end[jt[n + k]] < end[k]) end[jt[n + k]] = end[k];
    for (int a = 0; a < n; a++) {
        /* the lower part of row a, M^-1[a][r] (r <= a) = sum over k on a's path of X[a][k] X[r][k],
         * then mirrored into column a of the rows before */
        int l = lo[a];
        double *restrict row = Mb + off[a];
        for (int r = l; r <= a; r++) row[r - l] = 0.0;
        for (int k = a; k >= 0; k = jt[n + k]) {
            const double *restrict xr = Xb + off[k];
            double x = xr[a - l];
            int top = end[k] < a + 1 ? end[k] : a + 1;
            for (int r = k; r < top; r++) row[r - l] += x * xr[r - l];
        }
        for (int r = l; r < a; r++) Mb[off[r] + a - l] = row[r - l];
    }
    return FMUGEN_OK;
}

/* Recursive Newton-Euler at (q, qd, qdd) -- S, I, fx from kinematics() and external_forces() -- and
 * what its analytical derivatives need (see fmugen_chain_fd_jacobian): v, a, h, f, dv, w, uu (6n
 * each), al (12n), P, Q (6n), ev (3n, with external wrenches), the subtree sums ICn, Kn (36n), HCn,
 * Fn (6n), XS (16n), the lower triangle of M (n x n, rotor inertia included) and, when tauF is not
 * NULL, S_i . (the subtree's force) per joint. */
static void rnea_passes(int n, const int *jt, const double *lc, const double *g, const double *qd,
                        const double *qdd, const double *fxp, const double *cft, double *S, const double *I,
                        double *v, double *a, double *h, double *f, double *dv, double *w, double *uu, double *al,
                        double *P, double *Q, double *ev, double *ICn, double *Kn, double *HCn, double *Fn,
                        double *XS, double *M, double *tauF)
{
    /* forward: v_i, a_i, momenta h_i = I_i v_i, forces f_i = I_i a_i + v_i x* h_i, and per joint j
     * (parent pj) dv_j = S_j x v_pj, w_j = S_j x a_pj - dv_j x v_pj, u_j = 2 v_pj x S_j */
    const double a0[6] = {0.0, 0.0, 0.0, -g[0], -g[1], -g[2]};
    for (int i = 0; i < n; i++) {
        int par = jt[n + i];
        const double *vp = par >= 0 ? v + 6 * par : ZERO6, *ap = par >= 0 ? a + 6 * par : a0;
        double *Si = S + 6 * i, *vi = v + 6 * i, *ai = a + 6 * i, t[6], t2[6];
        crm(Si, vp, dv + 6 * i);
        crm(Si, ap, t);
        crm(dv + 6 * i, vp, t2);
        for (int k = 0; k < 6; k++) {
            w[6 * i + k] = t[k] - t2[k];
            uu[6 * i + k] = -2.0 * dv[6 * i + k];
        }
        for (int k = 0; k < 6; k++) vi[k] = vp[k] + Si[k] * qd[i];
        crm(vi, Si, t);
        for (int k = 0; k < 6; k++) ai[k] = ap[k] + Si[k] * qdd[i] + t[k] * qd[i];
        si_apply(I + SI_N * i, vi, h + 6 * i);
        si_apply(I + SI_N * i, ai, t);
        crf(vi, h + 6 * i, f + 6 * i);
        for (int k = 0; k < 6; k++) f[6 * i + k] += t[k] - (fxp ? fxp[6 * i + k] : 0.0);
    }
    /* backward: composite sums IC, K, HC, F over the subtree of i (each body's
     * own, then added to its parent's); the 12-vector al_i = [IC_i S_i ; K_i S_i +
     * gamma_i] (S_i . (x x* HC_i) = gamma_i . x) gives the entries of row i of dID
     * for the joints j on the path from i to the base, the vectors P_i, Q_i those
     * of column i for the joints before i; and M (lower) */
    memset(ICn, 0, (size_t)(SI_N + 48) * n * sizeof(double)); /* ICn, Kn, HCn, Fn */
    if (fxp) memset(XS, 0, (size_t)16 * n * sizeof(double));
    memset(M, 0, (size_t)n * n * sizeof(double));
    for (int i = n - 1; i >= 0; i--) {
        const double *L = lc + FMUGEN_CHAIN_NC * i;
        double *Si = S + 6 * i, t[6], t2[6], t3[6];
        const double *Ii = I + SI_N * i;
        double *IC = ICn + SI_N * i, *K = Kn + 36 * i, *HC = HCn + 6 * i, *F = Fn + 6 * i;
        int par = jt[n + i];
        for (int k = 0; k < SI_N; k++) IC[k] += Ii[k];
        add_K(K, Ii, v + 6 * i);
        for (int k = 0; k < 6; k++) {
            HC[k] += h[6 * i + k];
            F[k] += f[6 * i + k];
        }
        if (tauF) tauF[i] = dot6(Si, F); /* tau_i of recursive Newton-Euler, but rotor and friction */
        double *ali = al + 12 * i, *bgi = ali + 6, KS[6];
        si_apply(IC, Si, ali);
        mv6(K, Si, KS);
        /* gamma = [hn x s_w + hf x s_v ; hf x s_w] */
        cross3(HC, Si, t);
        cross3(HC + 3, Si + 3, t2);
        cross3(HC + 3, Si, t3);
        for (int k = 0; k < 3; k++) {
            bgi[k] = KS[k] + t[k] + t2[k];
            bgi[3 + k] = KS[3 + k] + t3[k];
        }
        /* P_i = IC u_i + K S_i + S_i x* HC ; Q_i = S_i x* F - (IC w_i + K dv_i + dv_i x* HC) */
        double *Pi = P + 6 * i, *Qi = Q + 6 * i;
        si_apply(IC, uu + 6 * i, Pi);
        crf(Si, HC, t2);
        for (int k = 0; k < 6; k++) Pi[k] += KS[k] + t2[k];
        crf(Si, F, Qi);
        si_apply(IC, w + 6 * i, t);
        mv6(K, dv + 6 * i, t2);
        crf(dv + 6 * i, HC, t3);
        for (int k = 0; k < 6; k++) Qi[k] -= t[k] + t2[k] + t3[k];
        double *xs = XS + 16 * i; /* subtree sums of c.f, t, f, c f^T */
        if (fxp) {
            /* external wrenches do not turn with the subtree: with the sums over
             * the subtree of t_k, f_k, c_k . f_k and c_k f_k^T, S_i . sum E_k(w) = e_i . w
             * for E_k(w) = [w x t_k + c_k x (w x f_k); w x f_k], and Q_i += sum E_k(w_i) */
            const double *ck = cft + 9 * i, *fk = ck + 3, *tk = ck + 6, *sw = Si, *sv = Si + 3;
            double *Ts = xs + 1, *Fs = xs + 4, *CFm = xs + 7;
            xs[0] += ck[0] * fk[0] + ck[1] * fk[1] + ck[2] * fk[2];
            for (int r = 0; r < 3; r++) {
                Ts[r] += tk[r];
                Fs[r] += fk[r];
                for (int k = 0; k < 3; k++) CFm[3 * r + k] += ck[r] * fk[k];
            }
            double CF = xs[0], *ei = ev + 3 * i, a1[3], a2[3], Ew[3];
            cross3(Ts, sw, a1);
            cross3(Fs, sv, a2);
            for (int r = 0; r < 3; r++)
                ei[r] = a1[r] + a2[r] + CF * sw[r] - (CFm[3 * r] * sw[0] + CFm[3 * r + 1] * sw[1] + CFm[3 * r + 2] * sw[2]);
            cross3(sw, Ts, a1); /* sum_k c_k x (w x f_k) = w (sum c_k . f_k) - (sum f_k c_k^T) w */
            for (int r = 0; r < 3; r++)
                Ew[r] = a1[r] + CF * sw[r] - (CFm[r] * sw[0] + CFm[3 + r] * sw[1] + CFm[6 + r] * sw[2]);
            cross3(sw, Fs, a2);
            for (int r = 0; r < 3; r++) {
                Qi[r] += Ew[r];
                Qi[3 + r] += a2[r];
            }
        }
        for (int j = i; j >= 0; j = jt[n + j]) M[(size_t)i * n + j] = dot6(ali, S + 6 * j);
        M[(size_t)i * n + i] += L[FMUGEN_CHAIN_ROTOR];
        if (par >= 0) {
            double *ICp = ICn + SI_N * par, *Kp = Kn + 36 * par, *xp = XS + 16 * par;
            for (int k = 0; k < SI_N; k++) ICp[k] += IC[k];
            for (int k = 0; k < 36; k++) Kp[k] += K[k];
            for (int k = 0; k < 6; k++) {
                HCn[6 * par + k] += HC[k];
                Fn[6 * par + k] += F[k];
            }
            if (fxp)
                for (int k = 0; k < 16; k++) xp[k] += xs[k];
        }
    }
}

/* The root branches: the subtree of each body whose parent is the base.  Joints on two of them
 * share no path, so M, M^-1 and the columns of M^-1 dID are block diagonal over them (Atlas:
 * 18 + 6 + 6 of 30 joints, Talos full 32 + 6 + 6 of 44): the dense work is done per block,
 * on the rows [lo_i, hi_i) of i's branch.  Bodies are numbered parents first, which need not
 * keep a branch contiguous: then one block of all n rows (the zeros are computed). */
static void root_blocks(int n, const int *jt, int *lo, int *hi)
{
    int contiguous = 1;
    for (int i = 0; i < n; i++) { /* lo: the root of i's branch; a branch broken by another is not contiguous */
        int par = jt[n + i];
        lo[i] = par >= 0 ? lo[par] : i;
        if (i > 0 && lo[i] != i && lo[i] != lo[i - 1]) contiguous = 0;
    }
    for (int i = 0; i < n; i++) hi[lo[i]] = i + 1; /* at the root: one past the branch's last body */
    for (int i = 0; i < n; i++) {
        if (contiguous) {
            hi[i] = hi[lo[i]];
        } else {
            lo[i] = 0;
            hi[i] = n;
        }
    }
}

/* off[i]: where row i of its block starts in a block-by-block n x n store (blocks one after
 * another, each nb x nb) */
static void block_offsets(int n, const int *lo, const int *hi, int *off)
{
    for (int i = 0, o = 0; i < n; i++) {
        int l = lo[i], nb = hi[i] - l;
        if (i == l) {
            off[i] = o;
            o += nb * nb;
        } else {
            off[i] = off[l] + (i - l) * nb;
        }
    }
}

int fmugen_chain_fd_jacobian(int n, const int *jt, const double *lc, const double *g, const double *q,
                             const double *qd, const double *tau, int ne, const int *ext_link,
                             const double *ext, double *qdd, double *dqdd, double *dp_ee, double *work)
{
    size_t nn = (size_t)n * n, n15 = (size_t)15 * n;
    double *R = work, *p = R + 9 * n, *S = p + 3 * n, *I = S + 6 * n, *IA = I + 36 * n, *v = IA + 36 * n;
    double *a = v + 6 * n, *h = a + 6 * n, *f = h + 6 * n, *dv = f + 6 * n, *w = dv + 6 * n;
    double *uu = w + 6 * n, *al = uu + 6 * n, *P = al + 12 * n, *Q = P + 6 * n;
    double *c = Q + 6 * n, *pA = c + 6 * n, *U = pA + 6 * n, *D = U + 6 * n, *u = D + n, *acc = u + n;
    double *fx = acc + 6 * n, *cft = fx + 6 * n, *ev = cft + 9 * n, *d = ev + 3 * n;
    double *ICn = d + n, *Kn = ICn + SI_N * n, *HCn = Kn + 36 * n, *Fn = HCn + 6 * n, *XS = Fn + 6 * n;
    double *M = XS + 16 * n, *A = M + nn, *Mb = A + nn, *Xq = Mb + nn, *Xd = Xq + nn;
    double *Hn = Xd + nn, *Gb = Hn + 6 * nn;
    int *gb = (int *)(Gb + 15 * nn), *freeb = gb + n, *path = freeb + n, *lo = path + n, *hi = lo + n;
    int *off = hi + n;
    double p_ee[3];
    kinematics(n, jt, lc, g, q, R, p, S, I, p_ee);
    const double *fxp = external_forces(n, ne, ext_link, ext, lc, R, p, fx, cft);
    /* forward dynamics first: the derivatives are those of ID at qdd = FD */
    int st = aba(n, jt, lc, g, qd, tau, fxp, S, I, IA, v, c, pA, U, D, u, acc, qdd);
    if (st != FMUGEN_OK) return st;
    rnea_passes(n, jt, lc, g, qd, qdd, fxp, cft, S, I, v, a, h, f, dv, w, uu, al, P, Q, ev, ICn, Kn, HCn, Fn, XS,
                M, NULL);
    /* M^-1 block by block: row j of block [lo, hi) at Mb + off[j], its nb entries contiguous */
    root_blocks(n, jt, lo, hi);
    block_offsets(n, lo, hi, off);
    st = tree_minv(n, jt, M, lo, hi, off, A, Mb, off + 2 * n); /* scratch past usesG (below) */
    if (st != FMUGEN_OK) return st;
    /* dqdd/dq = -Minv dID/dq, dqdd/dqd = -Minv dID/dqd, column by column, without forming dID:
     *   dID[i][j] (j on the path from i to the base) = -al_i . [w_j; dv_j]  (q),
     *                                                  al_i . [u_j; S_j] + b_j delta_ij  (qd)
     *   dID[i][j] (i before j, on its path)           =  S_i . Q_j  (q),   S_i . P_j  (qd)
     *   dID[i][j] = 0 for joints on different branches,
     * so column j of Minv dID is G_j W_j + H_pj Q_j with the sums over the subtree of j
     * G_j = sum_i Minv[:, i] al_i^T (nb x 12) and over the path from j to the base
     * H_j = sum_i Minv[:, i] S_i^T (nb x 6).  G and H are stored component-major (12 or 6 rows
     * of nb), so every update is an axpy over contiguous rows: the loops vectorise.  Column j
     * of the q and qd parts collects in Xq, Xd (nb entries each, stride n). */
    /* Two ways to the same columns, chosen per block by their cost in multiply-adds: the subtree
     * sums G, H above (54 per pair of rows of a block: long chains) or dID itself, whose entries
     * are nonzero only for a joint and the joints on its path to the base (d_i of them, d_i the
     * depth of i), each scattered as an axpy of a row of M^-1 (36 + 4 nb per pair on a path: the
     * branched trees and short chains).  usesG[j] marks the bodies of blocks taking the first. */
    int *usesG = off + n;
    for (int i = 0; i < n; i++) usesG[i] = -1;
    for (int i = 0; i < n; i++) {
        int l = lo[i];
        if (usesG[l] < 0) {
            long nb = hi[i] - l, pairs = 0;
            for (int k = l; k < hi[i]; k++)
                for (int j = k; j >= 0; j = jt[n + j]) pairs++;
            usesG[l] = pairs * (36 + 4 * nb) > 54 * nb * nb;
        }
        usesG[i] = usesG[l];
    }
    for (int j = 0; j < n; j++) {
        if (usesG[j]) continue;
        int nb = hi[j] - lo[j];
        double *xq = Xq + (size_t)n * j, *xd = Xd + (size_t)n * j;
        for (int r = 0; r < nb; r++) xq[r] = xd[r] = 0.0;
    }
    for (int i = 0; i < n; i++) {
        if (usesG[i]) continue;
        int nb = hi[i] - lo[i];
        const double *restrict Mi = Mb + off[i], *ali = al + 12 * i;
        /* not restrict: at j == i the columns of i and j are one */
        double *xqi = Xq + (size_t)n * i, *xdi = Xd + (size_t)n * i;
        for (int j = i; j >= 0; j = jt[n + j]) {
            const double *Sj = S + 6 * j;
            double *xqj = Xq + (size_t)n * j, *xdj = Xd + (size_t)n * j;
            /* i in the subtree of j: -dID[i][j] = al_i . [w_j; dv_j] (- e_i . s_w,j), and for qd
             * -(al_i . [u_j; S_j] + b_j delta_ij) */
            double cq = dot6(ali, w + 6 * j) + dot6(ali + 6, dv + 6 * j);
            double cd = -dot6(ali, uu + 6 * j) - dot6(ali + 6, Sj);
            if (fxp) cq -= ev[3 * i] * Sj[0] + ev[3 * i + 1] * Sj[1] + ev[3 * i + 2] * Sj[2];
            if (j == i) {
                double b;
                joint_friction(lc + FMUGEN_CHAIN_NC * i, qd[i], &b);
                cd -= b;
            }
            for (int r = 0; r < nb; r++) {
                xqj[r] += cq * Mi[r];
                xdj[r] += cd * Mi[r];
            }
            if (j != i) { /* j before i on its path: dID[j][i] = S_j . Q_i (q), S_j . P_i (qd) */
                const double *restrict Mj = Mb + off[j];
                double sq = -dot6(Sj, Q + 6 * i), sd = -dot6(Sj, P + 6 * i);
                for (int r = 0; r < nb; r++) {
                    xqi[r] += sq * Mj[r];
                    xdi[r] += sd * Mj[r];
                }
            }
        }
    }
    for (int j = 0; j < n; j++) { /* upper parts, j ascending (parents first) */
        if (!usesG[j]) continue;
        int par = jt[n + j], nb = hi[j] - lo[j];
        const double *Qj = Q + 6 * j, *Pj = P + 6 * j, *Sj = S + 6 * j;
        const double *restrict Mj = Mb + off[j];
        double *restrict Hj = Hn + 6 * (size_t)n * j, *restrict xq = Xq + (size_t)n * j;
        double *restrict xd = Xd + (size_t)n * j;
        if (par < 0) {
            for (int k = 0; k < 6; k++)
                for (int r = 0; r < nb; r++) Hj[k * nb + r] = Sj[k] * Mj[r];
            for (int r = 0; r < nb; r++) xq[r] = xd[r] = 0.0;
            continue;
        }
        const double *restrict Hp = Hn + 6 * (size_t)n * par;
        for (int r = 0; r < nb; r++) xq[r] = xd[r] = 0.0;
        for (int k = 0; k < 6; k++) {
            const double *restrict hp = Hp + k * nb;
            double *restrict hj = Hj + k * nb;
            double qk = -Qj[k], pk = -Pj[k], sk = Sj[k];
            for (int r = 0; r < nb; r++) {
                double t = hp[r];
                xq[r] += qk * t;
                xd[r] += pk * t;
                hj[r] = t + sk * Mj[r];
            }
        }
    }
    /* lower parts, j descending (children first): the subtree sum G of j lives in a buffer that
     * j's first finished child hands over (a chain: one buffer throughout); a leaf starts its own */
    int nfree = 0, nnew = 0, ng = fxp ? 15 : 12;
    for (int j = 0; j < n; j++) gb[j] = -1;
    for (int j = n - 1; j >= 0; j--) {
        if (!usesG[j]) continue;
        int nb = hi[j] - lo[j], fresh = gb[j] < 0;
        if (fresh) gb[j] = nfree ? freeb[--nfree] : nnew++;
        double *restrict G = Gb + n15 * gb[j];
        const double *restrict Mj = Mb + off[j];
        const double *alj = al + 12 * j;
        double *restrict xq = Xq + (size_t)n * j, *restrict xd = Xd + (size_t)n * j;
        double Wq[12], Wd[12], b;
        joint_friction(lc + FMUGEN_CHAIN_NC * j, qd[j], &b);
        b = -b; /* d(passive force)/dqd_j enters dID_j/dqd_j */
        for (int k = 0; k < 6; k++) {
            Wq[k] = w[6 * j + k];
            Wq[6 + k] = dv[6 * j + k];
            Wd[k] = -uu[6 * j + k];
            Wd[6 + k] = -S[6 * j + k];
        }
        for (int r = 0; r < nb; r++) xd[r] += b * Mj[r];
        for (int k = 0; k < 12; k++) {
            double *restrict gk = G + k * nb;
            double ak = alj[k], wq = Wq[k], wd = Wd[k];
            if (fresh) {
                for (int r = 0; r < nb; r++) {
                    double t = ak * Mj[r];
                    gk[r] = t;
                    xq[r] += wq * t;
                    xd[r] += wd * t;
                }
            } else {
                for (int r = 0; r < nb; r++) {
                    double t = gk[r] + ak * Mj[r];
                    gk[r] = t;
                    xq[r] += wq * t;
                    xd[r] += wd * t;
                }
            }
        }
        if (fxp) { /* dID[i][j] += e_i . w_j (i in the subtree of j): -M^-1 of it, by the sum Ge */
            const double *ej = ev + 3 * j, *wj = S + 6 * j;
            for (int k = 0; k < 3; k++) {
                double *restrict gk = G + (12 + k) * nb;
                double ek = ej[k], wk = wj[k];
                for (int r = 0; r < nb; r++) {
                    double t = (fresh ? 0.0 : gk[r]) + ek * Mj[r];
                    gk[r] = t;
                    xq[r] -= wk * t;
                }
            }
        }
        int par = jt[n + j];
        if (par >= 0) {
            if (gb[par] < 0) {
                gb[par] = gb[j];
            } else {
                double *restrict Gp = Gb + n15 * gb[par];
                size_t len = (size_t)ng * nb;
                for (size_t k = 0; k < len; k++) Gp[k] += G[k];
                freeb[nfree++] = gb[j];
            }
        } else {
            freeb[nfree++] = gb[j];
        }
    }
    /* the columns into the rows of dqdd; rows of other branches stay zero */
    size_t k3 = 3 * (size_t)n + 6 * (size_t)(ne > 0 ? ne : 0);
    memset(dqdd, 0, (size_t)n * k3 * sizeof(double));
    for (int j = 0; j < n; j++) {
        int l = lo[j], nb = hi[j] - l;
        const double *Mj = Mb + off[j], *xq = Xq + (size_t)n * j, *xd = Xd + (size_t)n * j;
        for (int r = 0; r < nb; r++) {
            double *row = dqdd + (size_t)(l + r) * k3;
            row[j] = xq[r];
            row[n + j] = xd[r];
            row[2 * n + j] = Mj[r];
        }
    }
    /* dqdd/dext = -M^-1 dID/dext: tau_i = ... - S_i . [t + c x f; f] for the joints i on the path
     * from body k to the base, so dID_i/df = -(s_w x c + s_v), dID_i/dt = -s_w */
    for (int e = 0; e < ne; e++) {
        int k = ext_link[e], np = 0, l = lo[k], nb = hi[k] - l;
        const double *ck = cft + 9 * k;
        for (int i = k; i >= 0; i = jt[n + i]) path[np++] = i;
        for (int comp = 0; comp < 6; comp++) {
            for (int t = 0; t < np; t++) {
                int i = path[t];
                const double *Si = S + 6 * i;
                double x[3];
                if (comp < 3) {
                    cross3(Si, ck, x);
                    d[t] = x[comp] + Si[3 + comp]; /* -dID_i/df_comp */
                } else {
                    d[t] = Si[comp - 3]; /* -dID_i/dt */
                }
            }
            size_t col = 3 * (size_t)n + 6 * (size_t)e + comp;
            for (int r = 0; r < nb; r++) { /* Minv[l + r][i] = row i of its block, entry r */
                double s = 0.0;
                for (int t = 0; t < np; t++) s += Mb[off[path[t]] + r] * d[t];
                dqdd[(size_t)(l + r) * k3 + col] = s;
            }
        }
    }
    /* (finiteness of the Jacobian is checked by the runtime that asked for it) */
    if (dp_ee) { /* point velocity of S_j at p_ee for the joints that move the end effector */
        memset(dp_ee, 0, (size_t)3 * n * sizeof(double));
        for (int j = jt[2 * n]; j >= 0; j = jt[n + j]) {
            double t[3], *Sj = S + 6 * j;
            cross3(Sj, p_ee, t);
            for (int r = 0; r < 3; r++) dp_ee[r * n + j] = Sj[3 + r] + t[r];
        }
    }
    return FMUGEN_OK;
}

/* M(q) by composite rigid bodies (CRBA): IC_i = I_i + sum over i's children of IC_c, and
 * M[i][j] = S_j . IC_i S_i for the joints j on i's path (zero between branches), the rotor
 * inertia on the diagonal.  M is n x n, both triangles written. */
static void crba(int n, const int *jt, const double *lc, const double *S, const double *I, double *IC, double *M)
{
    memcpy(IC, I, (size_t)SI_N * n * sizeof(double));
    memset(M, 0, (size_t)n * n * sizeof(double));
    for (int i = n - 1; i >= 0; i--) {
        double F[6];
        int par = jt[n + i];
        si_apply(IC + SI_N * i, S + 6 * i, F);
        for (int j = i; j >= 0; j = jt[n + j]) M[(size_t)i * n + j] = M[(size_t)j * n + i] = dot6(F, S + 6 * j);
        M[(size_t)i * n + i] += lc[FMUGEN_CHAIN_NC * i + FMUGEN_CHAIN_ROTOR];
        if (par >= 0)
            for (int k = 0; k < SI_N; k++) IC[SI_N * par + k] += IC[SI_N * i + k];
    }
}

int fmugen_chain_mass_matrix(int n, const int *jt, const double *lc, const double *g, const double *q, double *M,
                             double *work)
{
    double *R = work, *p = R + 9 * n, *S = p + 3 * n, *I = S + 6 * n, *IC = I + SI_N * n;
    kinematics(n, jt, lc, g, q, R, p, S, I, NULL);
    crba(n, jt, lc, S, I, IC, M);
    for (size_t k = 0; k < (size_t)n * n; k++)
        if (!isfinite(M[k])) return FMUGEN_NOT_FINITE;
    return FMUGEN_OK;
}

int fmugen_chain_mass_matrix_inverse(int n, const int *jt, const double *lc, const double *g, const double *q,
                                     double *Minv, double *work)
{
    size_t nn = (size_t)n * n;
    double *R = work, *p = R + 9 * n, *S = p + 3 * n, *I = S + 6 * n, *IC = I + SI_N * n;
    double *M = IC + SI_N * n, *Xb = M + nn, *Mb = Xb + nn;
    int *lo = (int *)(Mb + nn), *hi = lo + n, *off = hi + n, *end = off + n;
    kinematics(n, jt, lc, g, q, R, p, S, I, NULL);
    crba(n, jt, lc, S, I, IC, M);
    root_blocks(n, jt, lo, hi);
    block_offsets(n, lo, hi, off);
    int st = tree_minv(n, jt, M, lo, hi, off, Xb, Mb, end);
    if (st != FMUGEN_OK) return st;
    memset(Minv, 0, nn * sizeof(double));
    for (int i = 0; i < n; i++)
        memcpy(Minv + (size_t)i * n + lo[i], Mb + off[i], (size_t)(hi[i] - lo[i]) * sizeof(double));
    for (size_t k = 0; k < nn; k++)
        if (!isfinite(Minv[k])) return FMUGEN_NOT_FINITE;
    return FMUGEN_OK;
}

int fmugen_chain_id(int n, const int *jt, const double *lc, const double *g, const double *q, const double *qd,
                    const double *qdd, int ne, const int *ext_link, const double *ext, double *tau, double *work)
{
    double *R = work, *p = R + 9 * n, *S = p + 3 * n, *I = S + 6 * n, *v = I + 36 * n, *a = v + 6 * n;
    double *f = a + 6 * n, *fx = f + 6 * n, *cft = fx + 6 * n;
    kinematics(n, jt, lc, g, q, R, p, S, I, NULL);
    const double *fxp = external_forces(n, ne, ext_link, ext, lc, R, p, fx, cft);
    const double a0[6] = {0.0, 0.0, 0.0, -g[0], -g[1], -g[2]};
    for (int i = 0; i < n; i++) { /* base to leaves: v, a, f = I a + v x* I v - f_ext */
        int par = jt[n + i];
        const double *vp = par >= 0 ? v + 6 * par : ZERO6, *ap = par >= 0 ? a + 6 * par : a0, *Si = S + 6 * i;
        double *vi = v + 6 * i, *ai = a + 6 * i, t[6], hh[6];
        for (int k = 0; k < 6; k++) vi[k] = vp[k] + Si[k] * qd[i];
        crm(vi, Si, t);
        for (int k = 0; k < 6; k++) ai[k] = ap[k] + Si[k] * qdd[i] + t[k] * qd[i];
        si_apply(I + SI_N * i, vi, hh);
        crf(vi, hh, f + 6 * i);
        si_apply(I + SI_N * i, ai, t);
        for (int k = 0; k < 6; k++) f[6 * i + k] += t[k] - (fxp ? fxp[6 * i + k] : 0.0);
    }
    for (int i = n - 1; i >= 0; i--) { /* leaves to base: tau_i = S_i . (subtree force) + Ia qdd + friction */
        const double *L = lc + FMUGEN_CHAIN_NC * i;
        int par = jt[n + i];
        tau[i] = dot6(S + 6 * i, f + 6 * i) + L[FMUGEN_CHAIN_ROTOR] * qdd[i] + joint_friction(L, qd[i], NULL);
        if (par >= 0)
            for (int k = 0; k < 6; k++) f[6 * par + k] += f[6 * i + k];
    }
    for (int i = 0; i < n; i++)
        if (!isfinite(tau[i])) return FMUGEN_NOT_FINITE;
    return FMUGEN_OK;
}

int fmugen_chain_id_jacobian(int n, const int *jt, const double *lc, const double *g, const double *q,
                             const double *qd, const double *qdd, int ne, const int *ext_link, const double *ext,
                             double *tau, double *dtau, double *work)
{
    double *R = work, *p = R + 9 * n, *S = p + 3 * n, *I = S + 6 * n, *v = I + 36 * n;
    double *a = v + 6 * n, *h = a + 6 * n, *f = h + 6 * n, *dv = f + 6 * n, *w = dv + 6 * n;
    double *uu = w + 6 * n, *al = uu + 6 * n, *P = al + 12 * n, *Q = P + 6 * n;
    double *fx = Q + 6 * n, *cft = fx + 6 * n, *ev = cft + 9 * n;
    double *ICn = ev + 3 * n, *Kn = ICn + SI_N * n, *HCn = Kn + 36 * n, *Fn = HCn + 6 * n, *XS = Fn + 6 * n;
    double *M = XS + 16 * n;
    kinematics(n, jt, lc, g, q, R, p, S, I, NULL);
    const double *fxp = external_forces(n, ne, ext_link, ext, lc, R, p, fx, cft);
    rnea_passes(n, jt, lc, g, qd, qdd, fxp, cft, S, I, v, a, h, f, dv, w, uu, al, P, Q, ev, ICn, Kn, HCn, Fn, XS,
                M, tau);
    size_t k3 = 3 * (size_t)n + 6 * (size_t)(ne > 0 ? ne : 0);
    memset(dtau, 0, (size_t)n * k3 * sizeof(double));
    for (int i = 0; i < n; i++) {
        const double *L = lc + FMUGEN_CHAIN_NC * i, *ali = al + 12 * i;
        double slope, *row = dtau + i * k3;
        tau[i] += L[FMUGEN_CHAIN_ROTOR] * qdd[i] + joint_friction(L, qd[i], &slope);
        for (int j = i; j >= 0; j = jt[n + j]) { /* j on the path from i to the base (see the FD Jacobian) */
            double sq = 0.0, sd = 0.0;
            for (int k = 0; k < 6; k++) {
                sq -= ali[k] * w[6 * j + k] + ali[6 + k] * dv[6 * j + k];
                sd += ali[k] * uu[6 * j + k] + ali[6 + k] * S[6 * j + k];
            }
            if (fxp) sq += ev[3 * i] * S[6 * j] + ev[3 * i + 1] * S[6 * j + 1] + ev[3 * i + 2] * S[6 * j + 2];
            row[j] = sq;
            row[n + j] = sd + (j == i ? slope : 0.0);
            row[2 * n + j] = M[(size_t)i * n + j];
            if (j != i) { /* i lies beyond joint j: the upper entries of row j */
                double *rj = dtau + j * k3;
                rj[i] = dot6(S + 6 * j, Q + 6 * i);
                rj[n + i] = dot6(S + 6 * j, P + 6 * i);
                rj[2 * n + i] = M[(size_t)i * n + j];
            }
        }
        if (!isfinite(tau[i])) return FMUGEN_NOT_FINITE;
    }
    /* dtau/dext: tau_i = ... - S_i . [t + c x f; f] for the joints i on the path from body k to the base */
    for (int e = 0; e < ne; e++) {
        int k = ext_link[e];
        const double *ck = cft + 9 * k;
        for (int i = k; i >= 0; i = jt[n + i]) {
            const double *Si = S + 6 * i;
            double x[3], *row = dtau + i * k3 + 3 * (size_t)n + 6 * (size_t)e;
            cross3(Si, ck, x);
            for (int comp = 0; comp < 3; comp++) {
                row[comp] = -(x[comp] + Si[3 + comp]);
                row[3 + comp] = -Si[comp];
            }
        }
    }
    return FMUGEN_OK;
}
