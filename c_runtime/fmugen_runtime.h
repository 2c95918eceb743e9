/*
 * fmugen_runtime.h -- internal declarations shared by the files of the
 * hand-written FMI 2.0 runtime (not part of the model contract; generated
 * code only sees fmugen_model.h).
 *
 * An instance keeps everything in one struct: no global mutable state, so
 * any number of instances may live in one process and run in parallel
 * threads.
 */
#ifndef FMUGEN_RUNTIME_H
#define FMUGEN_RUNTIME_H

/* The runtime is C99 (declarations in for loops, designated initialisers):
 * say so, instead of hundreds of errors, under gcc's or clang's pre-C99
 * dialects (-std=gnu89, the default of gcc before 5).  MSVC defines no
 * __STDC_VERSION__ in its default mode and compiles the runtime. */
#if defined(__GNUC__) && (!defined(__STDC_VERSION__) || __STDC_VERSION__ < 199901L)
#error "fmugen's FMI runtime is C99: compile with -std=c99, -std=gnu99 or later (the default of gcc >= 5 and clang)"
#endif
#include <stddef.h>
#include "fmi2Functions.h"
#include "fmugen_model.h"

#if defined(__GNUC__) && defined(_WIN32)
/* PE: a DLL exports only what is marked dllexport (FMI2_Export), so no
 * visibility is needed; the log formats are C99's (MinGW's own printf,
 * runtime_support.c) */
#define FMUGEN_INTERNAL
#define FMUGEN_PRINTF(a, b) __attribute__((format(gnu_printf, a, b)))
#elif defined(__GNUC__)
#define FMUGEN_INTERNAL __attribute__((visibility("hidden")))
#define FMUGEN_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#define FMUGEN_INTERNAL
#define FMUGEN_PRINTF(a, b)
#endif

/* FMI 2.0 states of an instance (bit masks, so that the allowed states of a
 * function are one OR-ed constant). */
typedef enum {
    FMUGEN_INSTANTIATED = 1 << 0,
    FMUGEN_INITIALIZATION_MODE = 1 << 1,
    FMUGEN_EVENT_MODE = 1 << 2,           /* ME */
    FMUGEN_CONTINUOUS_TIME_MODE = 1 << 3, /* ME */
    FMUGEN_STEP_COMPLETE = 1 << 4,        /* CS */
    FMUGEN_STEP_FAILED = 1 << 5,          /* CS: fmi2DoStep returned fmi2Discard */
    FMUGEN_TERMINATED = 1 << 6,
    FMUGEN_ERROR = 1 << 7
} fmugen_fmi_state;

/* Log categories, in the order the modelDescription.xml declares them. */
typedef enum {
    FMUGEN_LOG_EVENTS = 0,
    FMUGEN_LOG_STATUS_WARNING = 1,
    FMUGEN_LOG_STATUS_ERROR = 2,
    FMUGEN_LOG_ALL = 3,
    FMUGEN_LOG_COUNT = 4
} fmugen_log_category;

FMUGEN_INTERNAL extern const char *const fmugen_log_category_names[FMUGEN_LOG_COUNT];

/* Everything that determines how a simulation continues, apart from the
 * arrays (x, u, du, ddu, dddu, p, fsal).  Copied as a whole by fmi2GetFMUstate, written
 * field by field by fmi2SerializeFMUstate. */
typedef struct fmugen_scalars {
    int fmi_state;             /* fmugen_fmi_state */
    double time;
    double start_time;
    int stop_time_defined;
    double stop_time;
    int rtol_set;              /* rtol given by fmi2SetReal: fmi2SetupExperiment's tolerance does not override it */
    double rt[FMUGEN_RT_COUNT];/* runtime Real parameters (rtol, atol, max_step, fixed_step) */
    int solver;                /* FMUGEN_SOLVER_* */
    long long n_steps, n_rejected, n_rhs, n_jac; /* solver counters */
    double h_next;             /* step size proposed for the next internal step, 0 = none yet */
    double facold;             /* previous error ratio of the Dormand-Prince controller */
    int fsal_valid;            /* fsal holds f(time, x, u) (Dormand-Prince first-same-as-last) */
    double last_successful_time;
    int last_do_step_status;   /* fmi2Status of the last fmi2DoStep */
    /* stiffness detection of Dormand-Prince (Hairer & Wanner's DOPRI5 test) */
    int stiff_run, nonstiff_run; /* consecutive stiff / non-stiff step tests */
    long long n_stiff;         /* stiffness detections so far (counter) */
    int stiff_logged;          /* the detection has been logged (once per instance) */
    /* RK4 stability limit from the Jacobian's dominant eigenvalue */
    double rk4_h_limit;        /* largest stable step, 0 = not known */
    double rk4_lambda;         /* |lambda| of the dominant eigenvalue [1/s] */
    double rk4_warned_limit;   /* limit of the last warning, 0 = none yet */
    double rk4_first_limit, rk4_first_lambda, rk4_first_time; /* the first warning's numbers, for the failure message */
    long long rk4_next_estimate; /* n_steps at which RK4 estimates its stability limit again */
    int range_check;           /* FMUGEN_RANGE_*: what leaving a validity range does */
    /* events (hybrid models) */
    long long n_events;        /* state events handled so far (CS: located in fmi2DoStep; ME: event iterations) */
    double last_event_time;    /* time of the last event */
    int storm_run;             /* consecutive events closer than FMUGEN_EVENT_STORM_GAP to the one before */
    int last_indicator;        /* index of the indicator of the last located event, -1 = none */
    int event_rounds;          /* ME: fmi2NewDiscreteStates rounds in the current event iteration */
    int x_reinit;              /* ME: a state was re-initialised in the current event iteration */
    int tick_done;             /* the clocks' ticks at tick_time have been processed */
    double tick_time;          /* time of the last processed tick */
    /* FMI 3.0 Co-Simulation with eventModeUsed: FMUGEN_PENDING_* bits of the event fmi2DoStep stopped at
     * (s.time) and left to the importer's Event Mode; 0 for FMI 2.0.  Part of fmi2GetFMUstate's copy, not
     * of the serialised form (fmu_state.c writes the FMI 2.0 fields). */
    int cs_event_pending;
} fmugen_scalars;

#define FMUGEN_PENDING_STATE_EVENT 1 /* a located state event: the event iteration has not run yet */
#define FMUGEN_PENDING_TICK 2        /* a sample instant: the clocks' event iteration has not run yet */

struct fmugen_ode;

/* What fmi2DoStep does beyond FMI 2.0 for an FMI 3.0 Co-Simulation instance that asked for it
 * (c_runtime/fmi3/fmi3_functions.c owns it).  An FMI 2.0 instance has none (fmugen_instance.cs_ext NULL),
 * and every step of it is exactly what it was before this existed. */
typedef struct fmugen_cs_ext {
    int event_mode_used;       /* eventModeUsed: an event ends the step unhandled, for the importer's Event Mode */
    int early_return_allowed;  /* earlyReturnAllowed: the step may end before tc + h */
    /* After each accepted internal solver step (solver.h, fmugen_step_accepted): the importer's
     * intermediate update.  1: the importer asked to return early (stop_at set), the solver stops here.
     * NULL: no callback. */
    int (*step_accepted)(struct fmugen_ode *ode);
    /* The inputs at time t inside the running step (solver.h, fmugen_ode_inputs): FMI 3.0's intermediate
     * update with intermediateVariableSetRequested, the importer setting them for t.  NULL: the
     * extrapolation polynomial from the communication point (fmugen_inputs_at), as for FMI 2.0. */
    void (*inputs_at)(struct fmugen_ode *ode, double t, double *out);
    double step_end;           /* tc + h of the running fmi2DoStep */
    double target;             /* where the running solver call ends (step_end, a sample instant, stop_at) */
    double stop_at;            /* the importer's earlyReturnTime in the running step; HUGE_VAL: none */
    int returned_early;        /* the last fmi2DoStep ended before tc + h */
} fmugen_cs_ext;

/* Tag of a live instance (fmugen_instance.tag), cleared by fmi2FreeInstance:
 * a second free, or a call on a freed instance whose memory has not been
 * reused yet, is recognised and refused instead of freeing twice.  A help,
 * not a guarantee: freed memory may be reused by anything. */
#define FMUGEN_INSTANCE_TAG 0x464D5547494E5354ULL /* "FMUGINST" */

typedef struct fmugen_instance {
    unsigned long long tag;    /* FMUGEN_INSTANCE_TAG while the instance lives */
    const fmugen_model_def *model;
    char *instance_name;
    fmi2Type type;
    fmi2CallbackFunctions cb;  /* copy: the importer's struct need not outlive the call */
    int logging_on;
    int log_category_on[FMUGEN_LOG_COUNT];

    fmugen_scalars s;

    /* one block: x[nx], u[nu], du[nu], ddu[nu], dddu[nu], p[np + nd] (the
     * parameters, then the discrete states), fsal[nx], zpre[nz] (the event
     * indicators at the last accepted point, whose domains a step compares) */
    double *vec;
    size_t n_vec;
    double *x, *u, *du, *ddu, *dddu, *p, *fsal, *zpre;
    /* event workspace (events.c): 5 nx + 3 nz + ng + na + 2 ns doubles */
    double *ev_work;

    /* cache of one model evaluation at (cache_time, x, u, p) */
    int cache_valid;
    int cache_status;
    double *dx_cache;          /* nx */
    double *y_cache;           /* ny */

    /* solver workspace, sized for the largest method */
    double *work;
    int *ipiv;
    /* vec at the start of the current communication step (n_vec: states,
     * inputs and their derivatives, discrete states, indicator memory):
     * fmi2DoStep puts it back when the end point fails its checks, so the
     * state is the last good point the message names */
    double *step_start;

    int range_messages;        /* validity-range warnings logged so far (bounded) */
    fmugen_cs_ext *cs_ext;     /* FMI 3.0 Co-Simulation extensions of fmi2DoStep; NULL for FMI 2.0 */
} fmugen_instance;

/* 1 for a live instance of this runtime: non-NULL and tagged (see FMUGEN_INSTANCE_TAG) */
static inline int fmugen_live(const struct fmugen_instance *inst)
{
    return inst != NULL && inst->tag == FMUGEN_INSTANCE_TAG;
}

/* ---- support (runtime_support.c) ---- */
FMUGEN_INTERNAL void fmugen_log(fmugen_instance *inst, fmi2Status status, fmugen_log_category cat,
                                const char *fmt, ...) FMUGEN_PRINTF(4, 5);
/* Returns 1 when inst is non-NULL and in one of the states of mask; else
 * logs "fn: not allowed in state S" and returns 0. */
FMUGEN_INTERNAL int fmugen_check_state(fmugen_instance *inst, int mask, const char *fn);
FMUGEN_INTERNAL const char *fmugen_state_name(int state);
/* Human-readable name of a Real value reference into buf, e.g. "der(x)". */
FMUGEN_INTERNAL const char *fmugen_real_name(const fmugen_instance *inst, fmi2ValueReference vr,
                                             char *buf, size_t n);
FMUGEN_INTERNAL void fmugen_invalidate(fmugen_instance *inst);
/* Evaluates the model at the current (time, x, u, p) unless cached; logs the
 * reason and returns a non-zero FMUGEN_* code when the model fails or gives a
 * non-finite result. */
FMUGEN_INTERNAL int fmugen_evaluate_cached(fmugen_instance *inst, const char *fn);
FMUGEN_INTERNAL const char *fmugen_model_status_text(int code);
FMUGEN_INTERNAL int fmugen_all_finite(const double *v, int n);
FMUGEN_INTERNAL void fmugen_set_defaults(fmugen_instance *inst);
static inline int fmugen_range_action(const fmugen_instance *inst) { return inst->s.range_check; }
static inline int fmugen_has_ranges(const fmugen_model_def *m)
{
    return m->x_min || m->x_max || m->u_min || m->u_max || m->y_min || m->y_max;
}

/* value-reference layout */
static inline fmi2ValueReference fmugen_vr_der(const fmugen_model_def *m) { return (fmi2ValueReference)m->nx; }
static inline fmi2ValueReference fmugen_vr_u(const fmugen_model_def *m) { return (fmi2ValueReference)(2 * m->nx); }
static inline fmi2ValueReference fmugen_vr_y(const fmugen_model_def *m) { return (fmi2ValueReference)(2 * m->nx + m->nu); }
static inline fmi2ValueReference fmugen_vr_p(const fmugen_model_def *m) { return (fmi2ValueReference)(2 * m->nx + m->nu + m->ny); }
static inline fmi2ValueReference fmugen_vr_rt(const fmugen_model_def *m) { return (fmi2ValueReference)(2 * m->nx + m->nu + m->ny + m->np); }
static inline fmi2ValueReference fmugen_vr_d(const fmugen_model_def *m) { return fmugen_vr_rt(m) + FMUGEN_RT_COUNT; }
/* a hybrid model's runtime Real after its discrete states: the time of the last event (solver.last_event_time) */
static inline fmi2ValueReference fmugen_vr_event_time(const fmugen_model_def *m) { return fmugen_vr_d(m) + (fmi2ValueReference)m->nd; }
static inline fmi2ValueReference fmugen_vr_end(const fmugen_model_def *m)
{
    return fmugen_vr_event_time(m) + ((m->nz > 0 || m->ng > 0 || m->ns > 0) ? 1u : 0u);
}

/* ---- events (events.c) ---- */
/* consecutive events each closer than this (times max(1, |t|)) to the one
 * before: an event storm (Zeno behaviour, chattering) after
 * FMUGEN_EVENT_STORM_RUN of them */
#define FMUGEN_EVENT_STORM_GAP 1e-9
#define FMUGEN_EVENT_STORM_RUN 100
/* rounds of the event iteration at one event instant */
#define FMUGEN_EVENT_MAX_ROUNDS 100
/* events located in one communication step */
#define FMUGEN_EVENT_MAX_PER_STEP 100000
/* an event is located to this time tolerance (times max(1, |t|)) */
#define FMUGEN_EVENT_TOL 1e-13
static inline int fmugen_has_events(const fmugen_model_def *m) { return m->nz > 0 || m->ng > 0 || m->ns > 0; }
/* The first tick of any clock strictly after t (a tick within the tolerance
 * of t counts as at t, not after): HUGE_VAL without clocks.  *at_t: some
 * clock ticks at t.  FMUGEN_OK, or a code when a period is not positive. */
FMUGEN_INTERNAL int fmugen_next_tick(fmugen_instance *inst, double t, double *next, int *at_t);
/* The event iteration at a tick at the current time: the ticking clocks'
 * flags are set for its first round.  FMUGEN_OK, or non-zero (msg). */
FMUGEN_INTERNAL int fmugen_tick_iteration(fmugen_instance *inst, const double *u, char *msg, size_t n);
/* One round of the clauses at the current time, the ticking clocks' flags set when this time's ticks have
 * not been processed yet (the first round at a sample instant); otherwise fmugen_event_round. */
FMUGEN_INTERNAL int fmugen_tick_round(fmugen_instance *inst, const double *u, int *changed, int *x_changed);
/* z = indicators at (t, x, u); FMUGEN_OK or a model/NOT_FINITE code */
FMUGEN_INTERNAL int fmugen_event_indicators(fmugen_instance *inst, double t, const double *x, const double *u,
                                            double *z);
/* One round of the clauses at (time, x, u): applies the firing assignments;
 * *changed: a discrete state or a state changed (*x_changed: a state).  FMUGEN_OK or a code. */
FMUGEN_INTERNAL int fmugen_event_round(fmugen_instance *inst, const double *u, int *changed, int *x_changed);
/* The whole event iteration at the current point (rounds until nothing
 * changes), then the indicators' domains remembered (zpre).  FMUGEN_OK, or
 * non-zero with the reason in msg. */
FMUGEN_INTERNAL int fmugen_event_iteration(fmugen_instance *inst, const double *u, char *msg, size_t n);
/* zpre = the indicators at the current point.  FMUGEN_OK or a code. */
FMUGEN_INTERNAL int fmugen_event_remember(fmugen_instance *inst, const double *u);
/* FMI 3.0 Co-Simulation Event Mode (fmi2_co_simulation.c): the event iteration of the event fmi2DoStep
 * stopped at (s.cs_event_pending), at the current time with the inputs inst->u -- the same iteration
 * fmi2DoStep runs inside the step without Event Mode; with nothing pending but inputs_changed, the
 * clauses' iteration for the new inputs.  Clears the pending bits.  FMUGEN_OK, or non-zero with the
 * reason in msg.  fn names the FMI function in the log message of a state event. */
FMUGEN_INTERNAL int fmugen_cs_event_update(fmugen_instance *inst, const char *fn, int inputs_changed, char *msg,
                                           size_t n);
/* Name of indicator i into buf */
FMUGEN_INTERNAL const char *fmugen_indicator_name(const fmugen_instance *inst, int i, char *buf, size_t n);

/* solver workspace: 10 nx + 2 nx^2 doubles for the methods (the implicit one
 * needs the most), then u0 and u(t) for the input extrapolation (2 nu) */
static inline size_t fmugen_solver_work_doubles(int nx) { return 10 * (size_t)nx + 2 * (size_t)nx * (size_t)nx; }
static inline size_t fmugen_workspace_doubles(int nx, int nu) { return fmugen_solver_work_doubles(nx) + 2 * (size_t)nu + 1; }

#endif
