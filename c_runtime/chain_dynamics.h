/*
 * chain_dynamics.h -- looped rigid-body dynamics of a serial chain, for
 * generated models past the size where straight-line code stops paying.
 *
 * A generated model.c of a large arm holds no dynamics: it evaluates the link
 * constants from the parameters (FMUGEN_CHAIN_NC numbers per link, layout
 * below) and calls these functions, which run Featherstone's articulated-body
 * algorithm and the analytical derivatives of recursive Newton-Euler as loops
 * over the links.  Everything is in base (world) coordinates, so no spatial
 * transform is ever applied to an inertia: a joint's motion subspace S_i, the
 * link inertias and the composite sums are all world quantities.
 *
 * Joint frames F_i (x to the next joint's common normal, z the joint axis):
 *     F_i = F_{i-1} Tx(a_i) Rx(alpha_i) Rz(theta0_i) Tz(d0_i) J_i(q_i),
 * J_i = Rz(q_i) (revolute) or Tz(q_i) (prismatic): the joint-frame form of
 * both Denavit-Hartenberg conventions (fmugen/dynamics/joint_frames.py).
 *
 * Sizes: n links; work arrays of FMUGEN_CHAIN_WORK(n) doubles supplied by the
 * caller (a local array of the generated function: no allocation, no state).
 */
#ifndef FMUGEN_CHAIN_DYNAMICS_H
#define FMUGEN_CHAIN_DYNAMICS_H

#include "fmugen_model.h"

/* per-link constants, in joint frame F_i (SI units) */
#define FMUGEN_CHAIN_COS_ALPHA 0
#define FMUGEN_CHAIN_SIN_ALPHA 1
#define FMUGEN_CHAIN_A 2        /* m */
#define FMUGEN_CHAIN_THETA0 3   /* rad */
#define FMUGEN_CHAIN_D0 4       /* m */
#define FMUGEN_CHAIN_MASS 5     /* kg */
#define FMUGEN_CHAIN_COM 6      /* 3: centre of mass, m, F_i */
#define FMUGEN_CHAIN_INERTIA 9  /* 6: about the COM, F_i axes: xx yy zz xy xz yz, kg m^2 */
#define FMUGEN_CHAIN_ROTOR 15   /* rotor inertia Ia (adds Ia qdd_i to tau_i), kg m^2 */
#define FMUGEN_CHAIN_DAMPING 16 /* viscous damping b (adds b qd_i to tau_i) */
#define FMUGEN_CHAIN_NC 17
/* global constants: gravity (3, base frame, m/s^2), then end_a (m): the
 * end effector is the origin of F_n Tx(end_a) */
#define FMUGEN_CHAIN_NG 4

/* doubles of work space for n links: forward dynamics, and its Jacobian */
#define FMUGEN_CHAIN_FD_WORK(n) (96 * (n) + 16)
#define FMUGEN_CHAIN_WORK(n) ((n) * (230 + 3 * (n)) + 64)

/* qdd = M(q)^{-1} (tau - h(q, qd)) by the articulated-body algorithm (O(n));
 * p_ee (3, may be NULL): end-effector position.  revolute[i] is 1 for a
 * revolute, 0 for a prismatic joint; lc is n x FMUGEN_CHAIN_NC, g is
 * FMUGEN_CHAIN_NG.  ne external wrenches act on the links ext_link[0..ne)
 * (0-based, each link at most once): ext is ne x 6, force (at the link's
 * centre of mass) and torque, base coordinates.  Returns FMUGEN_OK,
 * FMUGEN_NOT_POSITIVE_DEFINITE or FMUGEN_NOT_FINITE. */
FMUGEN_MODEL_HIDDEN int fmugen_chain_fd(int n, const int *revolute, const double *lc, const double *g,
                                        const double *q, const double *qd, const double *tau,
                                        int ne, const int *ext_link, const double *ext,
                                        double *qdd, double *p_ee, double *work);

/* The exact Jacobian of the forward dynamics at (q, qd, tau, ext):
 *   dqdd (n x (3n + 6 ne), row-major) = [dqdd/dq, dqdd/dqd, dqdd/dtau, dqdd/dext]
 *        = M^{-1} [-dID/dq, -dID/dqd, I, -dID/dext]  at qdd = FD(q, qd, tau, ext),
 * with dID from the analytical derivatives of recursive Newton-Euler in world
 * coordinates (O(n^2)) and one Cholesky factorisation of M (composite rigid
 * bodies).  qdd (n) receives the forward dynamics, dp_ee (3 x n, may be
 * NULL) the derivative of the end-effector position by q. */
FMUGEN_MODEL_HIDDEN int fmugen_chain_fd_jacobian(int n, const int *revolute, const double *lc, const double *g,
                                                 const double *q, const double *qd, const double *tau,
                                                 int ne, const int *ext_link, const double *ext,
                                                 double *qdd, double *dqdd, double *dp_ee, double *work);

#endif
