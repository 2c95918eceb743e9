/*
 * chain_dynamics.h -- looped rigid-body dynamics of a kinematic tree (a serial
 * chain is the special case), for generated models past the size where
 * straight-line code stops paying.
 *
 * A generated model.c of a large arm holds no dynamics: it evaluates the body
 * constants from the parameters (FMUGEN_CHAIN_NC numbers per body, layout
 * below) and calls these functions, which run Featherstone's articulated-body
 * algorithm and the analytical derivatives of recursive Newton-Euler as loops
 * over the bodies.  Everything is in base (world) coordinates, so no spatial
 * transform is ever applied to an inertia: a joint's motion subspace S_i, the
 * body inertias and the composite sums are all world quantities.
 *
 * Body frames F_i (the general joint model: a fixed placement, then the motion):
 *     F_i = F_{parent(i)} P_i J_i(q_i),   P_i = (R_i, p_i) constant,
 * J_i = rotation about the unit axis k_i by q_i (revolute) or translation
 * along k_i by q_i (prismatic), k_i in the placed frame F_{parent} P_i.  The
 * Denavit-Hartenberg joint-frame chain is the special case parent(i) = i - 1,
 * R_i = Rx(alpha_i) Rz(theta0_i), p_i = [a_i, -sin(alpha_i) d0_i,
 * cos(alpha_i) d0_i], k_i = z (fmugen/dynamics/joint_frames.py).
 *
 * Joint description: the int array `joint` holds 2n + 1 entries: joint[i] = 1
 * for a revolute, 0 for a prismatic joint; joint[n + i] = parent(i), -1 for
 * the base, else < i (bodies are numbered parents first); joint[2n] = the
 * body whose frame carries the end effector (-1: none, p_ee = 0).
 *
 * Sizes: n bodies; work arrays of FMUGEN_CHAIN_FD_WORK(n) / FMUGEN_CHAIN_WORK(n)
 * doubles supplied by the caller: no allocation, no state.
 */
#ifndef FMUGEN_CHAIN_DYNAMICS_H
#define FMUGEN_CHAIN_DYNAMICS_H

#include "fmugen_model.h"

/* per-body constants (SI units) */
#define FMUGEN_CHAIN_ROT 0      /* 9: R_i, placement rotation in the parent frame, row-major */
#define FMUGEN_CHAIN_POS 9      /* 3: p_i, placement origin in the parent frame, m */
#define FMUGEN_CHAIN_AXIS 12    /* 3: k_i, unit joint axis in the placed frame */
#define FMUGEN_CHAIN_MASS 15    /* kg */
#define FMUGEN_CHAIN_COM 16     /* 3: centre of mass, m, F_i */
#define FMUGEN_CHAIN_INERTIA 19 /* 6: about the COM, F_i axes: xx yy zz xy xz yz, kg m^2 */
#define FMUGEN_CHAIN_ROTOR 25   /* rotor inertia Ia (adds Ia qdd_i to tau_i), kg m^2 */
#define FMUGEN_CHAIN_DAMPING 26 /* viscous damping b (adds b qd_i to tau_i) */
#define FMUGEN_CHAIN_FRICTION 27 /* Coulomb level F_c: adds the smooth F_c tanh(qd_i / v_c) to tau_i (0: none) */
#define FMUGEN_CHAIN_FRICTION_VELOCITY 28 /* v_c, rad/s or m/s */
#define FMUGEN_CHAIN_NC 29
/* global constants: gravity (3, base frame, m/s^2), then the end effector's
 * position in the frame of body joint[2n] (3, m) */
#define FMUGEN_CHAIN_NG 6

/* doubles of work space for n bodies: forward dynamics, and its Jacobian */
#define FMUGEN_CHAIN_FD_WORK(n) (114 * (n) + 16)
#define FMUGEN_CHAIN_WORK(n) ((n) * (312 + 28 * (n)) + 64)

/* qdd = M(q)^{-1} (tau - h(q, qd)) by the articulated-body algorithm (O(n));
 * p_ee (3, may be NULL): end-effector position.  joint: see above; lc is
 * n x FMUGEN_CHAIN_NC, g is FMUGEN_CHAIN_NG.  ne external wrenches act on the
 * bodies ext_link[0..ne) (0-based, each body at most once): ext is ne x 6,
 * force (at the body's centre of mass) and torque, base coordinates.
 * Returns FMUGEN_OK, FMUGEN_NOT_POSITIVE_DEFINITE or FMUGEN_NOT_FINITE. */
FMUGEN_MODEL_HIDDEN int fmugen_chain_fd(int n, const int *joint, const double *lc, const double *g,
                                        const double *q, const double *qd, const double *tau,
                                        int ne, const int *ext_link, const double *ext,
                                        double *qdd, double *p_ee, double *work);

/* The exact Jacobian of the forward dynamics at (q, qd, tau, ext):
 *   dqdd (n x (3n + 6 ne), row-major) = [dqdd/dq, dqdd/dqd, dqdd/dtau, dqdd/dext]
 *        = M^{-1} [-dID/dq, -dID/dqd, I, -dID/dext]  at qdd = FD(q, qd, tau, ext),
 * with dID from the analytical derivatives of recursive Newton-Euler in world
 * coordinates (O(n d), d the depth of the tree) and a Cholesky factorisation
 * of M (composite rigid bodies) per root branch (M is block diagonal over them).  qdd (n) receives the forward dynamics, dp_ee
 * (3 x n, may be NULL) the derivative of the end-effector position by q. */
FMUGEN_MODEL_HIDDEN int fmugen_chain_fd_jacobian(int n, const int *joint, const double *lc, const double *g,
                                                 const double *q, const double *qd, const double *tau,
                                                 int ne, const int *ext_link, const double *ext,
                                                 double *qdd, double *dqdd, double *dp_ee, double *work);

/* M(q) (n x n, both triangles; rotor inertia on the diagonal) by composite rigid bodies, and
 * M(q)^-1 (n x n) from the tree factorisation M = L^T L without fill-in, per root branch.  work:
 * FMUGEN_CHAIN_FD_WORK(n) doubles for M, FMUGEN_CHAIN_WORK(n) for M^-1. */
FMUGEN_MODEL_HIDDEN int fmugen_chain_mass_matrix(int n, const int *joint, const double *lc, const double *g,
                                                 const double *q, double *M, double *work);
FMUGEN_MODEL_HIDDEN int fmugen_chain_mass_matrix_inverse(int n, const int *joint, const double *lc,
                                                         const double *g, const double *q, double *Minv,
                                                         double *work);

/* tau = ID(q, qd, qdd, ext) = M qdd + h (+ rotor inertia, damping, friction) by recursive Newton-Euler,
 * O(n); work: FMUGEN_CHAIN_FD_WORK(n) doubles. */
FMUGEN_MODEL_HIDDEN int fmugen_chain_id(int n, const int *joint, const double *lc, const double *g,
                                        const double *q, const double *qd, const double *qdd,
                                        int ne, const int *ext_link, const double *ext, double *tau, double *work);

/* tau and its exact Jacobian dtau (n x (3n + 6 ne), row-major) = [dID/dq, dID/dqd, M, dID/dext],
 * the same analytical derivatives as the forward dynamics' Jacobian without the solve;
 * work: FMUGEN_CHAIN_WORK(n) doubles. */
FMUGEN_MODEL_HIDDEN int fmugen_chain_id_jacobian(int n, const int *joint, const double *lc, const double *g,
                                                 const double *q, const double *qd, const double *qdd,
                                                 int ne, const int *ext_link, const double *ext,
                                                 double *tau, double *dtau, double *work);

#endif
