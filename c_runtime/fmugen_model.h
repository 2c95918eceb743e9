/*
 * fmugen_model.h -- the contract between generated model code and the
 * hand-written FMI 2.0 runtime.
 *
 * Generated code (model.c) holds only the model: sizes, start values, names,
 * and two pure functions.  Everything FMI -- the state machine, value
 * references, logging, the Co-Simulation solvers, FMU state -- lives in the
 * runtime and works for any model that fills in this struct.
 *
 * The model is   dx/dt = f(t, x, u, p),   y = g(t, x, u, p).
 *
 * Value references of fmi2Real variables (contiguous blocks, in this order):
 *   [0, nx)                         states x
 *   [nx, 2nx)                       derivatives der(x)
 *   [2nx, 2nx+nu)                   inputs u
 *   [2nx+nu, 2nx+nu+ny)             computed outputs y
 *   [2nx+nu+ny, 2nx+nu+ny+np)       parameters p
 *   then the runtime's own Real parameters (FMUGEN_RT_* offsets below),
 *   then the nd discrete states d of a hybrid model (see "Events" below).
 * States that are also outputs keep the value reference of the state.
 * fmi2Integer value references: FMUGEN_INT_* below.
 */
#ifndef FMUGEN_MODEL_H
#define FMUGEN_MODEL_H

#ifdef __cplusplus
extern "C" {
#endif

/* status codes returned by evaluate/jacobian */
#define FMUGEN_OK 0
#define FMUGEN_NOT_POSITIVE_DEFINITE 1 /* mass matrix Cholesky failed */
#define FMUGEN_NOT_FINITE 2            /* a result is NaN or Inf */

/* runtime Real parameters, offset from first_runtime_vr = 2nx+nu+ny+np */
#define FMUGEN_RT_RTOL 0      /* relative tolerance of the CS solver */
#define FMUGEN_RT_ATOL 1      /* absolute tolerance (scaled by x_nominal) */
#define FMUGEN_RT_MAX_STEP 2  /* largest internal step, 0 = no limit */
#define FMUGEN_RT_FIXED_STEP 3 /* step of the fixed-step methods, 0 = one step per communication step */
#define FMUGEN_RT_COUNT 4

/* fmi2Integer value references */
#define FMUGEN_INT_SOLVER 0     /* parameter: 1 Dormand-Prince 5(4), 2 implicit (stiff), 3 RK4 fixed step */
#define FMUGEN_INT_N_STEPS 1    /* local: accepted internal steps so far */
#define FMUGEN_INT_N_REJECTED 2 /* local: rejected internal steps so far */
#define FMUGEN_INT_N_RHS 3      /* local: evaluations of f so far */
#define FMUGEN_INT_N_JAC 4      /* local: evaluations of the Jacobian so far */
#define FMUGEN_INT_STIFFNESS_DETECTED 5 /* local: times Dormand-Prince found the problem stiff so far */
#define FMUGEN_INT_RANGE_CHECK 6 /* parameter: what leaving a validity range does, FMUGEN_RANGE_* */
#define FMUGEN_INT_N_EVENTS 7   /* local: events handled so far (hybrid models) */
#define FMUGEN_INT_COUNT 8

/* values of the range_check parameter (validity ranges: x_min ... below) */
#define FMUGEN_RANGE_IGNORE 0 /* not checked */
#define FMUGEN_RANGE_WARN 1   /* default: fmi2DoStep returns fmi2Warning and logs the variable */
#define FMUGEN_RANGE_ERROR 2  /* fmi2DoStep returns fmi2Discard */

#define FMUGEN_SOLVER_DOPRI5 1
#define FMUGEN_SOLVER_IMPLICIT 2
#define FMUGEN_SOLVER_RK4 3

typedef struct fmugen_model_def {
    const char *model_identifier;
    const char *guid;
    int nx, nu, ny, np;
    const double *x_start;   /* nx */
    const double *x_nominal; /* nx, for error scaling */
    const double *u_start;   /* nu */
    const double *p_start;   /* np */
    const char *const *x_names;
    const char *const *u_names;
    const char *const *y_names;
    const char *const *p_names;
    int has_jacobian;

    /* Computes der(x) into dx (length nx) and y (length ny) in one pass;
     * either pointer may be NULL when not wanted.  Returns FMUGEN_OK or an
     * error code.  Pure: no state kept between calls. */
    int (*evaluate)(const double *p, double t, const double *x, const double *u,
                    double *dx, double *y);

    /* Exact partial derivatives, dense row-major: dfdx nx*nx, dfdu nx*nu,
     * dgdx ny*nx, dgdu ny*nu.  Any pointer may be NULL.  NULL function when
     * has_jacobian is 0. */
    int (*jacobian)(const double *p, double t, const double *x, const double *u,
                    double *dfdx, double *dfdu, double *dgdx, double *dgdu);

    /* Validity ranges of states (nx), inputs (nu) and computed outputs (ny):
     * the model's equations hold only for min <= v <= max (a pressure up to
     * the supply, a positive chamber volume, a spool within its stroke).
     * -HUGE_VAL / HUGE_VAL where a side is open; NULL pointers: no range.
     * Checked by the Co-Simulation runtime after every communication step. */
    const double *x_min, *x_max;
    const double *u_min, *u_max;
    const double *y_min, *y_max;

    /* Start values of the runtime's own parameters that differ from its
     * defaults (a scene's internal solver and tolerances, baked in so that
     * every importer integrates as the scene does): rt_start holds
     * FMUGEN_RT_RTOL..FMUGEN_RT_FIXED_STEP (NULL: the defaults), solver_start
     * a FMUGEN_SOLVER_* (0: the default).  modelDescription.xml states the
     * same values as start. */
    const double *rt_start;
    int solver_start;

    /* Physical ranges of the parameters (np), the min/max of modelDescription.xml
     * (a mass or an inertia > 0 is written as min = DBL_MIN, the smallest
     * positive normal double): fmi2SetReal refuses a value outside them and
     * changes nothing.  NULL: no range. */
    const double *p_min, *p_max;

    /* ---- Events (hybrid models; all 0/NULL for a smooth model) ----
     * nz event indicators z = indicators(p, t, x, u): a state event when some
     * z_i changes its domain z_i > 0 <-> z_i <= 0 (FMI 2.0 sec. 3.1).
     * nd discrete states d, stored right after the parameters, p[np .. np+nd):
     * evaluate, jacobian and indicators read them as parameters (constant
     * between events).  At an event, update(p, t, x, u, guard, value) computes
     * from the values before the event the ng guards (1 = the clause fires) and
     * the na assigned values; the runtime then writes value[a] to
     * assign_target[a] (k < nd: d_k; nd + j: the state x_j, a
     * re-initialisation) for every a whose clause guard[assign_clause[a]] holds,
     * and repeats until no discrete state and no state changes (the event
     * iteration). */
    int nz, nd, ng, na;
    const char *const *z_names; /* nz: what each indicator watches (messages) */
    const double *d_start;      /* nd */
    const char *const *d_names; /* nd */
    int (*indicators)(const double *p, double t, const double *x, const double *u, double *z);
    int (*update)(const double *p, double t, const double *x, const double *u, double *guard, double *value);
    const int *assign_clause; /* na */
    const int *assign_target; /* na */

    /* ---- Clocks (sampled components; all 0/NULL without) ----
     * ns clocks tick at t = offset_k + j period_k (j = 0, 1, ...): time
     * events.  clocks(p, period, offset) gives them from the parameters (a
     * period > 0, checked at initialisation); clock_tick[k] is the index in d
     * of clock k's tick flag, which the runtime sets to 1 for the first round
     * of the event iteration at each of its ticks (and to 0 otherwise), so a
     * clause guarded by it fires once per sample instant. */
    int ns;
    int (*clocks)(const double *p, double *period, double *offset);
    const int *clock_tick; /* ns */
} fmugen_model_def;

/* Symbols shared by the runtime and model.c but not part of the FMU's
 * interface: hidden, so the shared library exports only the fmi2* functions
 * (no other library's fmugen_model can be bound in their place, and an
 * importer sees nothing it may not call). */
#if defined(__GNUC__) && !defined(_WIN32)
#define FMUGEN_MODEL_HIDDEN __attribute__((visibility("hidden")))
#else
#define FMUGEN_MODEL_HIDDEN
#endif

/* Defined by the generated model.c */
FMUGEN_MODEL_HIDDEN extern const fmugen_model_def fmugen_model;

/* Provided by the runtime (linalg.c): solves A X = B for symmetric positive
 * definite A (n x n, row-major, only the lower triangle read, overwritten by
 * its Cholesky factor) and B (n x k, row-major, overwritten by X).  Returns
 * FMUGEN_OK or FMUGEN_NOT_POSITIVE_DEFINITE. */
FMUGEN_MODEL_HIDDEN int fmugen_spd_solve(int n, int k, double *A, double *B);

#ifdef __cplusplus
}
#endif
#endif
