/*
 * fmu_state.c -- fmi2GetFMUstate / SetFMUstate / FreeFMUstate and the
 * serialisation of FMU states.
 *
 * A snapshot holds everything that determines how the simulation continues:
 * the FMI state, time, start/stop time, states x, inputs u, input
 * derivatives du, ddu, dddu, parameters p, runtime parameters and solver choice, the
 * solver's memory (proposed next step, controller history, first-same-as-
 * last derivative) and the counters.  Restoring it reproduces the
 * continuation bit for bit.  (Logging settings are not part of it.)
 *
 * Serialised form (native byte order, for the same platform):
 *   8 bytes  magic "FMUGENST"
 *   u32      format version (2: with the stiffness and stability monitors; 3: with range_check;
 *            4: with second input derivatives; 5: with third input derivatives; 6: with the
 *            event memory)
 *   u32      fmuType
 *   u32 x 4  nx, nu, ny, np
 *   u32      length of the GUID, then the GUID bytes (no terminator)
 *   i64/f64  the scalar fields, in the order of put_scalars()
 *   u64      number of doubles, then the doubles x, u, du, ddu, dddu, p (with the discrete
 *            states after the parameters), fsal, zpre (the event indicators' last values)
 *   u64      FNV-1a hash of all preceding bytes
 * A blob with another magic, version, GUID, size or hash is refused with
 * fmi2Error and a message saying which check failed.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "fmugen_runtime.h"

#define SNAPSHOT_MAGIC 0x464D5547u /* "FMUG" */
#define FORMAT_VERSION 6u
static const char blob_magic[8] = {'F', 'M', 'U', 'G', 'E', 'N', 'S', 'T'};

typedef struct fmugen_snapshot {
    uint32_t magic;
    uint64_t model_hash; /* FNV-1a of the model identifier and GUID of the FMU that took it */
    int type;
    size_t n_vec;
    fmugen_scalars s;
    double vec[]; /* n_vec */
} fmugen_snapshot;

#define INST ((fmugen_instance *)c)
#define ANY_STATE                                                                                     \
    (FMUGEN_INSTANTIATED | FMUGEN_INITIALIZATION_MODE | FMUGEN_EVENT_MODE | FMUGEN_CONTINUOUS_TIME_MODE | \
     FMUGEN_STEP_COMPLETE | FMUGEN_STEP_FAILED | FMUGEN_TERMINATED | FMUGEN_ERROR)
#define CHECK_STATE(fn) \
    if (!fmugen_check_state(INST, ANY_STATE, (fn))) return fmi2Error

static fmi2Status fail(fmugen_instance *inst, const char *fn, const char *why)
{
    fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: %s", fn, why);
    return fmi2Error;
}

static size_t snapshot_bytes(const fmugen_instance *inst)
{
    return sizeof(fmugen_snapshot) + inst->n_vec * sizeof(double);
}

static void *rt_alloc(fmugen_instance *inst, size_t bytes)
{
    return inst->cb.allocateMemory ? inst->cb.allocateMemory(1, bytes) : calloc(1, bytes);
}

static void rt_free(fmugen_instance *inst, void *p)
{
    if (inst->cb.freeMemory) inst->cb.freeMemory(p);
    else free(p);
}

static uint64_t fnv1a_more(uint64_t h, const unsigned char *p, size_t n)
{
    for (size_t i = 0; i < n; i++) { h ^= p[i]; h *= 1099511628211ULL; }
    return h;
}

static uint64_t fnv1a(const unsigned char *p, size_t n) { return fnv1a_more(1469598103934665603ULL, p, n); }

/* Identity of the model: another FMU (another GUID) with the same sizes
 * must not pass its state off as this one's.  Instances of the same FMU,
 * also loaded twice, share it. */
static uint64_t model_hash(const fmugen_model_def *m)
{
    uint64_t h = fnv1a((const unsigned char *)m->model_identifier, strlen(m->model_identifier) + 1);
    return fnv1a_more(h, (const unsigned char *)m->guid, strlen(m->guid));
}

/* Why state cannot be a state of this instance's FMU and type, or NULL
 * when it can. */
static const char *snapshot_problem(const fmugen_instance *inst, fmi2FMUstate state)
{
    const fmugen_snapshot *snap = (const fmugen_snapshot *)state;
    if (!snap) return "it is NULL";
    if (snap->magic != SNAPSHOT_MAGIC) return "it is not an fmugen FMU state (or was freed)";
    if (snap->model_hash != model_hash(inst->model))
        return "it was taken from another FMU (another model identifier or GUID)";
    if (snap->type != (int)inst->type) return "it was taken from an instance of the other FMU type (ME/CS)";
    if (snap->n_vec != inst->n_vec) return "its sizes differ from this model's";
    return NULL;
}

/* A snapshot of this instance's FMU and type, or NULL. */
static fmugen_snapshot *as_snapshot(const fmugen_instance *inst, fmi2FMUstate state)
{
    return snapshot_problem(inst, state) ? NULL : (fmugen_snapshot *)state;
}

static fmugen_snapshot *new_snapshot(fmugen_instance *inst)
{
    fmugen_snapshot *snap = rt_alloc(inst, snapshot_bytes(inst));
    if (snap) {
        snap->magic = SNAPSHOT_MAGIC;
        snap->model_hash = model_hash(inst->model);
        snap->type = (int)inst->type;
        snap->n_vec = inst->n_vec;
    }
    return snap;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    CHECK_STATE("fmi2GetFMUstate");
    fmugen_instance *inst = INST;
    if (!FMUstate) return fail(inst, "fmi2GetFMUstate", "FMUstate is NULL");
    fmugen_snapshot *snap = NULL;
    if (*FMUstate) {
        /* the standard lets the importer pass an earlier state to overwrite */
        snap = as_snapshot(inst, *FMUstate);
        if (!snap) return fail(inst, "fmi2GetFMUstate", "*FMUstate is neither NULL nor a state of this FMU");
    } else {
        snap = new_snapshot(inst);
        if (!snap) return fail(inst, "fmi2GetFMUstate", "out of memory");
    }
    snap->s = inst->s;
    memcpy(snap->vec, inst->vec, inst->n_vec * sizeof(double));
    *FMUstate = snap;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    CHECK_STATE("fmi2SetFMUstate");
    fmugen_instance *inst = INST;
    const char *why = snapshot_problem(inst, FMUstate);
    if (why) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2SetFMUstate: the FMU state is refused, nothing changed: %s (this FMU: %s, GUID %s)", why,
                   inst->model->model_identifier, inst->model->guid);
        return fmi2Error;
    }
    const fmugen_snapshot *snap = (const fmugen_snapshot *)FMUstate;
    inst->s = snap->s;
    memcpy(inst->vec, snap->vec, inst->n_vec * sizeof(double));
    fmugen_invalidate(inst);
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    CHECK_STATE("fmi2FreeFMUstate");
    fmugen_instance *inst = INST;
    if (!FMUstate || !*FMUstate) return fmi2OK;
    fmugen_snapshot *snap = as_snapshot(inst, *FMUstate);
    if (!snap) return fail(inst, "fmi2FreeFMUstate", "*FMUstate is not a state of this FMU");
    snap->magic = 0; /* a second free or a stale use is recognised */
    rt_free(inst, snap);
    *FMUstate = NULL;
    return fmi2OK;
}

/* ---- serialisation ---- */

typedef struct writer {
    unsigned char *p; /* NULL: only count */
    size_t n;
} writer;

static void put(writer *w, const void *v, size_t k)
{
    if (w->p) memcpy(w->p + w->n, v, k);
    w->n += k;
}
static void put_u32(writer *w, uint32_t v) { put(w, &v, 4); }
static void put_i64(writer *w, long long v) { int64_t x = v; put(w, &x, 8); }
static void put_f64(writer *w, double v) { put(w, &v, 8); }

static void put_scalars(writer *w, const fmugen_scalars *s)
{
    put_i64(w, s->fmi_state);
    put_f64(w, s->time);
    put_f64(w, s->start_time);
    put_i64(w, s->stop_time_defined);
    put_f64(w, s->stop_time);
    put_i64(w, s->rtol_set);
    for (int k = 0; k < FMUGEN_RT_COUNT; k++) put_f64(w, s->rt[k]);
    put_i64(w, s->solver);
    put_i64(w, s->n_steps);
    put_i64(w, s->n_rejected);
    put_i64(w, s->n_rhs);
    put_i64(w, s->n_jac);
    put_f64(w, s->h_next);
    put_f64(w, s->facold);
    put_i64(w, s->fsal_valid);
    put_f64(w, s->last_successful_time);
    put_i64(w, s->last_do_step_status);
    put_i64(w, s->stiff_run);
    put_i64(w, s->nonstiff_run);
    put_i64(w, s->n_stiff);
    put_i64(w, s->stiff_logged);
    put_f64(w, s->rk4_h_limit);
    put_f64(w, s->rk4_lambda);
    put_f64(w, s->rk4_warned_limit);
    put_f64(w, s->rk4_first_limit);
    put_f64(w, s->rk4_first_lambda);
    put_f64(w, s->rk4_first_time);
    put_i64(w, s->rk4_next_estimate);
    put_i64(w, s->range_check);
    put_i64(w, s->n_events);
    put_f64(w, s->last_event_time);
    put_i64(w, s->storm_run);
    put_i64(w, s->last_indicator);
    put_i64(w, s->event_rounds);
    put_i64(w, s->x_reinit);
    put_i64(w, s->tick_done);
    put_f64(w, s->tick_time);
}

typedef struct reader {
    const unsigned char *p;
    size_t n, pos;
    int bad;
} reader;

static void get(reader *r, void *v, size_t k)
{
    if (r->bad || r->pos + k > r->n) { r->bad = 1; memset(v, 0, k); return; }
    memcpy(v, r->p + r->pos, k);
    r->pos += k;
}
static uint32_t get_u32(reader *r) { uint32_t v; get(r, &v, 4); return v; }
static long long get_i64(reader *r) { int64_t v; get(r, &v, 8); return (long long)v; }
static double get_f64(reader *r) { double v; get(r, &v, 8); return v; }

static void get_scalars(reader *r, fmugen_scalars *s)
{
    memset(s, 0, sizeof *s);
    s->fmi_state = (int)get_i64(r);
    s->time = get_f64(r);
    s->start_time = get_f64(r);
    s->stop_time_defined = (int)get_i64(r);
    s->stop_time = get_f64(r);
    s->rtol_set = (int)get_i64(r);
    for (int k = 0; k < FMUGEN_RT_COUNT; k++) s->rt[k] = get_f64(r);
    s->solver = (int)get_i64(r);
    s->n_steps = get_i64(r);
    s->n_rejected = get_i64(r);
    s->n_rhs = get_i64(r);
    s->n_jac = get_i64(r);
    s->h_next = get_f64(r);
    s->facold = get_f64(r);
    s->fsal_valid = (int)get_i64(r);
    s->last_successful_time = get_f64(r);
    s->last_do_step_status = (int)get_i64(r);
    s->stiff_run = (int)get_i64(r);
    s->nonstiff_run = (int)get_i64(r);
    s->n_stiff = get_i64(r);
    s->stiff_logged = (int)get_i64(r);
    s->rk4_h_limit = get_f64(r);
    s->rk4_lambda = get_f64(r);
    s->rk4_warned_limit = get_f64(r);
    s->rk4_first_limit = get_f64(r);
    s->rk4_first_lambda = get_f64(r);
    s->rk4_first_time = get_f64(r);
    s->rk4_next_estimate = get_i64(r);
    s->range_check = (int)get_i64(r);
    s->n_events = get_i64(r);
    s->last_event_time = get_f64(r);
    s->storm_run = (int)get_i64(r);
    s->last_indicator = (int)get_i64(r);
    s->event_rounds = (int)get_i64(r);
    s->x_reinit = (int)get_i64(r);
    s->tick_done = (int)get_i64(r);
    s->tick_time = get_f64(r);
}


static void serialize(const fmugen_instance *inst, const fmugen_snapshot *snap, writer *w)
{
    const fmugen_model_def *m = inst->model;
    put(w, blob_magic, 8);
    put_u32(w, FORMAT_VERSION);
    put_u32(w, (uint32_t)snap->type);
    put_u32(w, (uint32_t)m->nx);
    put_u32(w, (uint32_t)m->nu);
    put_u32(w, (uint32_t)m->ny);
    put_u32(w, (uint32_t)m->np);
    uint32_t glen = (uint32_t)strlen(m->guid);
    put_u32(w, glen);
    put(w, m->guid, glen);
    put_scalars(w, &snap->s);
    put_i64(w, (long long)snap->n_vec);
    for (size_t i = 0; i < snap->n_vec; i++) put_f64(w, snap->vec[i]);
    uint64_t h = w->p ? fnv1a(w->p, w->n) : 0;
    put(w, &h, 8);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    CHECK_STATE("fmi2SerializedFMUstateSize");
    fmugen_instance *inst = INST;
    const fmugen_snapshot *snap = as_snapshot(inst, FMUstate);
    if (!snap) return fail(inst, "fmi2SerializedFMUstateSize", "FMUstate is NULL or not a state of this FMU");
    if (!size) return fail(inst, "fmi2SerializedFMUstateSize", "size is NULL");
    writer w = {NULL, 0};
    serialize(inst, snap, &w);
    *size = w.n;
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    CHECK_STATE("fmi2SerializeFMUstate");
    fmugen_instance *inst = INST;
    const fmugen_snapshot *snap = as_snapshot(inst, FMUstate);
    if (!snap) return fail(inst, "fmi2SerializeFMUstate", "FMUstate is NULL or not a state of this FMU");
    if (!serializedState) return fail(inst, "fmi2SerializeFMUstate", "serializedState is NULL");
    writer count = {NULL, 0};
    serialize(inst, snap, &count);
    if (size != count.n) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR,
                   "fmi2SerializeFMUstate: size %zu differs from fmi2SerializedFMUstateSize = %zu", size, count.n);
        return fmi2Error;
    }
    writer w = {(unsigned char *)serializedState, 0};
    serialize(inst, snap, &w);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    CHECK_STATE("fmi2DeSerializeFMUstate");
    fmugen_instance *inst = INST;
    const fmugen_model_def *m = inst->model;
    const char *fn = "fmi2DeSerializeFMUstate";
    if (!FMUstate) return fail(inst, fn, "FMUstate is NULL");
    if (!serializedState && size > 0) return fail(inst, fn, "serializedState is NULL");
    reader r = {(const unsigned char *)serializedState, size, 0, 0};
    if (size < 16) return fail(inst, fn, "the blob is too short to be an fmugen FMU state");
    char magic[8];
    get(&r, magic, 8);
    if (memcmp(magic, blob_magic, 8) != 0) return fail(inst, fn, "not an fmugen FMU state (bad magic)");
    if (get_u32(&r) != FORMAT_VERSION) return fail(inst, fn, "unsupported FMU state format version");
    uint32_t type = get_u32(&r);
    uint32_t dims[4];
    for (int k = 0; k < 4; k++) dims[k] = get_u32(&r);
    uint32_t glen = get_u32(&r);
    if (r.bad || glen > size - r.pos) return fail(inst, fn, "truncated blob (GUID)");
    if (glen != strlen(m->guid) || memcmp(r.p + r.pos, m->guid, glen) != 0)
        return fail(inst, fn, "the state belongs to an FMU with another GUID");
    r.pos += glen;
    if (type != (uint32_t)inst->type) return fail(inst, fn, "the state belongs to the other FMU type (ME/CS)");
    if (dims[0] != (uint32_t)m->nx || dims[1] != (uint32_t)m->nu || dims[2] != (uint32_t)m->ny ||
        dims[3] != (uint32_t)m->np)
        return fail(inst, fn, "the state's sizes nx, nu, ny, np differ from this model's");
    fmugen_scalars s;
    get_scalars(&r, &s);
    long long nvec = get_i64(&r);
    if (r.bad || nvec != (long long)inst->n_vec) return fail(inst, fn, "truncated blob or wrong number of values");
    size_t expected = r.pos + inst->n_vec * 8 + 8;
    if (size != expected) {
        fmugen_log(inst, fmi2Error, FMUGEN_LOG_STATUS_ERROR, "%s: blob has %zu bytes, expected %zu", fn, size,
                   expected);
        return fmi2Error;
    }
    uint64_t h_stored;
    memcpy(&h_stored, r.p + size - 8, 8);
    if (h_stored != fnv1a(r.p, size - 8)) return fail(inst, fn, "checksum mismatch: the blob is corrupted");
    /* semantic checks: a consistent blob with impossible contents */
    int st = s.fmi_state;
    if (st <= 0 || st > FMUGEN_ERROR || (st & (st - 1)) != 0) return fail(inst, fn, "invalid FMI state in blob");
    if (s.solver < FMUGEN_SOLVER_DOPRI5 || s.solver > FMUGEN_SOLVER_RK4) return fail(inst, fn, "invalid solver in blob");
    if (s.range_check < FMUGEN_RANGE_IGNORE || s.range_check > FMUGEN_RANGE_ERROR)
        return fail(inst, fn, "invalid range_check in blob");
    if (s.n_events < 0 || s.storm_run < 0 || s.event_rounds < 0 || (s.x_reinit & ~1) || !isfinite(s.last_event_time) ||
        (s.tick_done & ~1) || !isfinite(s.tick_time) ||
        s.last_indicator < -1 || s.last_indicator >= (m->nz > 0 ? m->nz : 0))
        return fail(inst, fn, "invalid event memory (counters, last event) in blob");
    if (!isfinite(s.time)) return fail(inst, fn, "non-finite time in blob");
    /* everything fmi2SetReal/fmi2SetupExperiment would refuse is refused
     * here too: a restored state must be one the API could have produced */
    if (!isfinite(s.start_time) || !isfinite(s.stop_time) || !isfinite(s.last_successful_time) ||
        s.last_successful_time > s.time)
        return fail(inst, fn, "invalid start, stop or last successful time in blob");
    if ((s.stop_time_defined & ~1) || (s.rtol_set & ~1) || (s.fsal_valid & ~1) || (s.stiff_logged & ~1))
        return fail(inst, fn, "a flag in the blob is not 0 or 1");
    if (!(s.rt[FMUGEN_RT_RTOL] > 0 && s.rt[FMUGEN_RT_RTOL] < 1) || !(s.rt[FMUGEN_RT_ATOL] > 0) ||
        !isfinite(s.rt[FMUGEN_RT_ATOL]) || !(s.rt[FMUGEN_RT_MAX_STEP] >= 0) || !isfinite(s.rt[FMUGEN_RT_MAX_STEP]) ||
        !(s.rt[FMUGEN_RT_FIXED_STEP] >= 0) || !isfinite(s.rt[FMUGEN_RT_FIXED_STEP]))
        return fail(inst, fn, "a runtime parameter (rtol, atol, max_step, fixed_step) in the blob is out of range");
    if (!(s.h_next >= 0) || !isfinite(s.h_next) || !isfinite(s.facold))
        return fail(inst, fn, "invalid solver memory (step size, controller history) in blob");
    if (s.n_steps < 0 || s.n_rejected < 0 || s.n_rhs < 0 || s.n_jac < 0 || s.n_stiff < 0)
        return fail(inst, fn, "negative counter in blob");
    if (s.last_do_step_status < fmi2OK || s.last_do_step_status > fmi2Error)
        return fail(inst, fn, "invalid last fmi2DoStep status in blob");
    {
        reader v = r; /* the arrays x, u, du, ddu, dddu, p, fsal: finite, as fmi2SetReal would have them */
        const size_t p0 = (size_t)m->nx + 4 * (size_t)m->nu;
        for (size_t i = 0; i < inst->n_vec; i++) {
            const double d = get_f64(&v);
            if (!isfinite(d)) return fail(inst, fn, "non-finite value (state, input, parameter) in blob");
            if (i >= p0 && i < p0 + (size_t)m->np &&
                ((m->p_min && d < m->p_min[i - p0]) || (m->p_max && d > m->p_max[i - p0])))
                return fail(inst, fn, "a parameter in the blob is outside its physical range");
        }
    }
    fmugen_snapshot *snap = *FMUstate ? as_snapshot(inst, *FMUstate) : new_snapshot(inst);
    if (!snap) return fail(inst, fn, *FMUstate ? "*FMUstate is not a state of this FMU" : "out of memory");
    snap->s = s;
    for (size_t i = 0; i < inst->n_vec; i++) snap->vec[i] = get_f64(&r);
    *FMUstate = snap;
    return fmi2OK;
}
