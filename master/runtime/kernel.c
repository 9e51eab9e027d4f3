/* The stepping kernel (see kernel.h): one macro step of one component, the start-up sweeps, the
 * macro-step loop with recording and real-time pacing. */
#define _GNU_SOURCE /* syscall (futex), clock_nanosleep */
#include "kernel.h"
#include "solvers.h" /* the fixed-step methods and the LU of fmus/solvers, shared with the project's FMUs */

#include <float.h>
#include <limits.h>
#include <linux/futex.h>
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <string.h>
#include <sched.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

/* FMI 2.0 and 3.0 calls, spelled with their ABI types (no FMI headers needed to build). */
typedef int fmi2_do_step(void *, double, double, int);
typedef int fmi2_set_real(void *, const uint32_t *, size_t, const double *);
typedef int fmi2_get_real(void *, const uint32_t *, size_t, double *);
typedef int fmi2_set_derivatives(void *, const uint32_t *, size_t, const int32_t *, const double *);
typedef int fmi2_get_integer(void *, const uint32_t *, size_t, int32_t *);
typedef int fmi2_get_boolean(void *, const uint32_t *, size_t, int32_t *);
typedef int fmi2_set_integer(void *, const uint32_t *, size_t, const int32_t *);
typedef int fmi2_set_boolean(void *, const uint32_t *, size_t, const int32_t *);
/* FMI 1.0 Co-Simulation: the FMI 2 shapes but for fmiBoolean, one byte (fmiDoStep's newStep too) */
typedef char fmi1_boolean;
typedef int fmi1_do_step(void *, double, double, fmi1_boolean);
typedef int fmi1_get_boolean(void *, const uint32_t *, size_t, fmi1_boolean *);
typedef int fmi1_set_boolean(void *, const uint32_t *, size_t, const fmi1_boolean *);
typedef int fmi3_do_step(void *, double, double, bool, bool *, bool *, bool *, double *);
typedef int fmi3_set_float64(void *, const uint32_t *, size_t, const double *, size_t);
typedef int fmi3_get_float64(void *, const uint32_t *, size_t, double *, size_t);
typedef int fmi3_get_int32(void *, const uint32_t *, size_t, int32_t *, size_t);
typedef int fmi3_get_boolean(void *, const uint32_t *, size_t, bool *, size_t);
typedef int fmi3_set_int32(void *, const uint32_t *, size_t, const int32_t *, size_t);
typedef int fmi3_set_boolean(void *, const uint32_t *, size_t, const bool *, size_t);
typedef int fmi2_get_directional_derivative(void *, const uint32_t *, size_t, const uint32_t *, size_t, const double *,
                                            double *);
typedef int fmi3_get_directional_derivative(void *, const uint32_t *, size_t, const uint32_t *, size_t, const double *,
                                            size_t, double *, size_t);
typedef int fmi_get_state(void *, void **);
typedef int fmi_set_state(void *, void *);
typedef int fmi_free_state(void *, void **);
typedef int fmi2_get_boolean_status(void *, int, int32_t *);
typedef int fmi2_get_string(void *, const uint32_t *, size_t, const char **);
typedef int fmi2_set_string(void *, const uint32_t *, size_t, const char *const *);
typedef int fmi3_get_string(void *, const uint32_t *, size_t, const char **, size_t);
typedef int fmi3_set_string(void *, const uint32_t *, size_t, const char *const *, size_t);
typedef int fmi3_get_binary(void *, const uint32_t *, size_t, size_t *, const uint8_t **, size_t);
typedef int fmi3_set_binary(void *, const uint32_t *, size_t, const size_t *, const uint8_t *const *, size_t);
/* Model Exchange (FMI 2 and 3 alike but for the Booleans of fmi2/3CompletedIntegratorStep) */
typedef int fmi_set_time(void *, double);
typedef int fmi_set_states(void *, const double *, size_t);
typedef int fmi_get_states(void *, double *, size_t);
typedef int fmi2_completed_step(void *, int, int32_t *, int32_t *);
typedef int fmi3_completed_step(void *, bool, bool *, bool *);
typedef int fmi_mode(void *); /* fmi2/3EnterEventMode, fmi2/3EnterContinuousTimeMode */
typedef struct {
    int32_t new_discrete_states_needed, terminate_simulation, nominals_changed, values_changed, next_event_time_defined;
    double next_event_time;
} fmi2_event_info;
typedef int fmi2_new_discrete_states(void *, fmi2_event_info *);
typedef int fmi3_update_discrete_states(void *, bool *, bool *, bool *, bool *, bool *, double *);
#define FMI2_DISCARD 2
#define FMI2_TERMINATED 3 /* fmi2StatusKind fmi2Terminated */

#define STATUS_OK 1 /* fmi2Warning / fmi3Warning: anything above is a failure */

void mk_layout(int64_t *sizes) {
    sizes[0] = (int64_t)sizeof(mk_link);
    sizes[1] = (int64_t)sizeof(mk_stimulus);
    sizes[2] = (int64_t)sizeof(mk_component);
    sizes[3] = (int64_t)sizeof(mk_record);
    sizes[4] = (int64_t)sizeof(mk_error);
    sizes[5] = (int64_t)sizeof(mk_pacing);
    sizes[6] = (int64_t)sizeof(mk_kernel);
    sizes[7] = (int64_t)sizeof(mk_counter);
    sizes[8] = (int64_t)sizeof(mk_shared);
    sizes[9] = (int64_t)sizeof(mk_call);
    sizes[10] = (int64_t)sizeof(mk_transform);
    sizes[11] = (int64_t)sizeof(mk_loop);
    sizes[12] = (int64_t)sizeof(mk_intermediate);
    sizes[13] = (int64_t)sizeof(mk_scheduled);
}

void mk_constants(int64_t *values) {
    values[0] = MK_KINDS;
    values[1] = MK_COUPLING_ERROR;
    values[2] = MK_ERROR_FIELDS;
    values[3] = MK_STRING_SLOT;
    values[4] = MK_TEXT_MAX;
    values[5] = MK_TRANSFORM_NONE;
    values[6] = MK_TRANSFORM_LINEAR;
    values[7] = MK_TRANSFORM_MAP;
    values[8] = MK_LOOP_NEWTON;
    values[9] = MK_LOOP_FIXED_POINT;
    values[10] = MK_EDGE_ASSUMED;
    values[11] = MK_LOOP_STATS;
    values[12] = SOLVER_COUNT; /* the shared solvers (model.h), numbered 1 .. SOLVER_COUNT */
}

static int64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static double point_time(const mk_component *c, int64_t j) {
    return (double)(c->num0 + j * c->dnum) / (double)c->den;
}

/* A call of the FMI 3 typed functions, as the failing calls below report it: MK_CALL_SET_TYPED or
 * MK_CALL_GET_TYPED with the value kind in the bits above the lowest 8 (fail splits them). */
#define TYPED_CALL(call, kind) ((call) | (kind) << 8)

static int32_t fail(mk_kernel *k, int32_t code, int32_t comp, int32_t call, int32_t status, int64_t j) {
    k->error.code = code;
    k->error.component = comp;
    k->error.call = call < 0 ? call : call & 0xff;
    k->error.kind = call < 0 ? 0 : call >> 8;
    k->error.status = status;
    k->error.point = j;
    k->error.variable = -1;
    k->error.value = 0.0;
    k->error.integer = 0;
    return code;
}

/* -- synchronisation between processes ----------------------------------------------------------- */

#define BUSY_SPIN_NS 5000 /* a waiter polls without yielding this long */

static int64_t load(const mk_counter *c) { return __atomic_load_n(&c->value, __ATOMIC_SEQ_CST); }

static void futex(mk_counter *c, int op, int32_t value, const struct timespec *timeout) {
    /* the low 32 bits of the counter (x86-64 is little-endian): any advance changes them */
    syscall(SYS_futex, (int32_t *)&c->value, op, value, timeout, NULL, 0);
}

/* Set c to v and wake whoever sleeps on it. */
static void publish(mk_counter *c, int64_t v) {
    __atomic_store_n(&c->value, v, __ATOMIC_SEQ_CST);
    if (__atomic_load_n(&c->waiters, __ATOMIC_SEQ_CST)) futex(c, FUTEX_WAKE, INT_MAX, NULL);
}

static int64_t advance(mk_counter *c, int64_t by) {
    int64_t v = __atomic_add_fetch(&c->value, by, __ATOMIC_SEQ_CST);
    if (__atomic_load_n(&c->waiters, __ATOMIC_SEQ_CST)) futex(c, FUTEX_WAKE, INT_MAX, NULL);
    return v;
}

/* Wait until c >= target: spin for spin_ns (yielding after BUSY_SPIN_NS), then sleep in the futex
 * (waking every 10 ms to see the cancel flag). MK_ABORTED if the run is cancelled meanwhile. */
static int32_t wait_for(mk_kernel *k, mk_counter *c, int64_t target) {
    mk_shared *sh = k->shared;
    if (load(c) >= target) return MK_DONE;
    int64_t t = now_ns(), spin_end = t + sh->spin_ns, busy_end = t + BUSY_SPIN_NS;
    while ((t = now_ns()) < spin_end) {
        for (int i = 0; i < 64; i++) {
            if (load(c) >= target) return MK_DONE;
            __builtin_ia32_pause();
        }
        /* after a few microseconds, yield between polls: should the producer share this
         * processor, it runs now instead of after the spin */
        if (t > busy_end) sched_yield();
    }
    const struct timespec tick = {0, 10000000};
    for (;;) {
        if (load(sh->cancel) || k->n_now >= load(sh->stop_at)) return MK_ABORTED;
        __atomic_add_fetch(&c->waiters, 1, __ATOMIC_SEQ_CST);
        int64_t v = load(c);
        if (v < target) futex(c, FUTEX_WAIT, (int32_t)v, &tick);
        __atomic_sub_fetch(&c->waiters, 1, __ATOMIC_SEQ_CST);
        if (load(c) >= target) return MK_DONE;
    }
}

static int32_t aborted(mk_kernel *k) {
    k->error.code = MK_ABORTED;
    return MK_ABORTED;
}

/* Every worker arrives before any goes on (start-up sweeps); MK_ABORTED if the run is cancelled. */
static int32_t barrier(mk_kernel *k) {
    if (!k->shared) return MK_DONE;
    int64_t target = ++k->barriers * k->shared->n_workers;
    advance(k->shared->barrier, 1);
    return wait_for(k, k->shared->barrier, target) ? aborted(k) : MK_DONE;
}

void mk_publish(mk_counter *c, int64_t value) { publish(c, value); }

/* Wake every process sleeping on a counter, to see a cancel or a stop. */
static void wake_all(mk_shared *s, int32_t n_components, int32_t n_workers) {
    for (int32_t i = 0; i < n_components; i++) {
        futex(&s->published[i], FUTEX_WAKE, INT_MAX, NULL);
        futex(&s->stepped[i], FUTEX_WAKE, INT_MAX, NULL);
        futex(&s->consumed[i], FUTEX_WAKE, INT_MAX, NULL);
        if (s->swept) futex(&s->swept[i], FUTEX_WAKE, INT_MAX, NULL);
    }
    for (int32_t w = 0; w < n_workers; w++) futex(&s->rows_written[w], FUTEX_WAKE, INT_MAX, NULL);
    futex(s->barrier, FUTEX_WAKE, INT_MAX, NULL);
    futex(s->rows_drained, FUTEX_WAKE, INT_MAX, NULL);
}

void mk_cancel(mk_shared *s, int32_t n_components, int32_t n_workers) {
    publish(s->cancel, 1);
    wake_all(s, n_components, n_workers);
}

/* Lower the shared stop to n_stop, never raise it (requests may race), and wake every waiter. */
static void lower_stop(mk_shared *s, int64_t n_stop, int32_t n_components, int32_t n_workers) {
    int64_t cur = load(s->stop_at);
    while (n_stop < cur &&
           !__atomic_compare_exchange_n(&s->stop_at->value, &cur, n_stop, false, __ATOMIC_SEQ_CST, __ATOMIC_SEQ_CST)) {
    }
    wake_all(s, n_components, n_workers);
}

void mk_stop(mk_shared *s, int64_t n_stop, int32_t n_components, int32_t n_workers) {
    lower_stop(s, n_stop, n_components, n_workers);
}

/* The first macro step no process may begin (an FMU ended the simulation), INT64_MAX if none. */
static int64_t stop_at(const mk_kernel *k) { return k->shared ? load(k->shared->stop_at) : k->stop_at; }

/* Component ci ended the simulation at point j: no macro step from n_stop on. */
static void request_stop(mk_kernel *k, int32_t ci, int64_t j, int64_t n_stop) {
    mk_shared *sh = k->shared;
    if (!sh) {
        if (n_stop < k->stop_at) {
            k->stop_at = n_stop;
            k->stopper[0] = ci;
            k->stopper[1] = j;
        }
        return;
    }
    /* per component, written by its own process only: the earliest request is found afterwards */
    sh->stopper[2 * ci] = n_stop;
    sh->stopper[2 * ci + 1] = j;
    lower_stop(sh, n_stop, k->n_components, sh->n_workers);
}

/* Whether macro step n is repeated from saved FMU states: a start-up step, or every one when iterated. */
static bool repeated(const mk_kernel *k, int64_t n) { return n < k->startup_steps || k->iterate; }

/* Whether macro step n records a row: every record_every macro steps, and the last. Every process
 * records the same macro steps, so the rows of the ring line up. */
static bool row_due(const mk_kernel *k, int64_t n) { return (n + 1) % k->record_every == 0 || n + 1 == k->n_macro; }

/* -- FMI calls by version ----------------------------------------------------------------------- */

/* Each call moves n values of nvr value references (FMI 3: fewer where arrays are among them, an
 * array's elements in a row; FMI 2, and every scalar: nvr == n). */
static int set_real(const mk_component *c, const uint32_t *vrs, int32_t nvr, const double *v, int32_t n) {
    if (c->fmi == 3) return ((fmi3_set_float64 *)c->set_real)(c->instance, vrs, (size_t)nvr, v, (size_t)n);
    return ((fmi2_set_real *)c->set_real)(c->instance, vrs, (size_t)n, v);
}

static int get_real(const mk_component *c, const uint32_t *vrs, int32_t nvr, double *v, int32_t n) {
    if (c->fmi == 3) return ((fmi3_get_float64 *)c->get_real)(c->instance, vrs, (size_t)nvr, v, (size_t)n);
    return ((fmi2_get_real *)c->get_real)(c->instance, vrs, (size_t)n, v);
}

/* Integer (kind MK_INTEGER) or Boolean values v[0..n) of value references vrs, from doubles. */
static int set_discrete(const mk_component *c, int32_t kind, const uint32_t *vrs, int32_t nvr, const double *v,
                        int32_t n) {
    int32_t iv[n];
    bool bv[n];
    fmi1_boolean cv[n];
    for (int32_t i = 0; i < n; i++) {
        iv[i] = kind == MK_INTEGER ? (int32_t)v[i] : v[i] != 0.0;
        bv[i] = v[i] != 0.0;
        cv[i] = v[i] != 0.0;
    }
    if (kind == MK_INTEGER)
        return c->fmi == 3 ? ((fmi3_set_int32 *)c->set_integer)(c->instance, vrs, (size_t)nvr, iv, (size_t)n)
                           : ((fmi2_set_integer *)c->set_integer)(c->instance, vrs, (size_t)n, iv);
    if (c->fmi == 1) return ((fmi1_set_boolean *)c->set_boolean)(c->instance, vrs, (size_t)n, cv);
    return c->fmi == 3 ? ((fmi3_set_boolean *)c->set_boolean)(c->instance, vrs, (size_t)nvr, bv, (size_t)n)
                       : ((fmi2_set_boolean *)c->set_boolean)(c->instance, vrs, (size_t)n, iv);
}

static int get_discrete(const mk_component *c, int32_t kind, const uint32_t *vrs, int32_t nvr, double *v,
                        int32_t n) {
    int32_t iv[n];
    bool bv[n];
    fmi1_boolean cv[n];
    int st;
    if (kind == MK_INTEGER)
        st = c->fmi == 3 ? ((fmi3_get_int32 *)c->get_integer)(c->instance, vrs, (size_t)nvr, iv, (size_t)n)
                         : ((fmi2_get_integer *)c->get_integer)(c->instance, vrs, (size_t)n, iv);
    else if (c->fmi == 3)
        st = ((fmi3_get_boolean *)c->get_boolean)(c->instance, vrs, (size_t)nvr, bv, (size_t)n);
    else if (c->fmi == 1)
        st = ((fmi1_get_boolean *)c->get_boolean)(c->instance, vrs, (size_t)n, cv);
    else
        st = ((fmi2_get_boolean *)c->get_boolean)(c->instance, vrs, (size_t)n, iv);
    for (int32_t i = 0; i < n; i++)
        v[i] = kind == MK_BOOLEAN && c->fmi == 3   ? (bv[i] ? 1.0 : 0.0)
               : kind == MK_BOOLEAN && c->fmi == 1 ? (cv[i] ? 1.0 : 0.0)
               : kind == MK_BOOLEAN                ? (iv[i] ? 1.0 : 0.0)
                                                   : (double)iv[i];
    return st;
}

/* n FMI 3 values of kind MK_FLOAT32 ... MK_UINT64 through fmi3Set<type> (kernel.h: set_typed), from
 * doubles: a Float32 is rounded to float, an integer is exact (the plan hands over whole values in
 * the type's range: a producer's samples of the same type, or checked stimuli). */
#define SET_TYPED(T)                                                                                 \
    {                                                                                                \
        T x[n];                                                                                      \
        typedef int set_t(void *, const uint32_t *, size_t, const T *, size_t);                     \
        for (int32_t i = 0; i < n; i++) x[i] = (T)v[i];                                              \
        return ((set_t *)c->set_typed[kind])(c->instance, vrs, (size_t)nvr, x, (size_t)n);           \
    }

static int set_typed(const mk_component *c, int32_t kind, const uint32_t *vrs, int32_t nvr, const double *v,
                     int32_t n) {
    switch (kind) {
    case MK_FLOAT32: SET_TYPED(float)
    case MK_INT8: SET_TYPED(int8_t)
    case MK_UINT8: SET_TYPED(uint8_t)
    case MK_INT16: SET_TYPED(int16_t)
    case MK_UINT16: SET_TYPED(uint16_t)
    case MK_UINT32: SET_TYPED(uint32_t)
    case MK_INT64: SET_TYPED(int64_t)
    case MK_UINT64: SET_TYPED(uint64_t)
    case MK_CLOCK_COUNT: return 0; /* a linked clock ticks through its activation (scheduled.c) */
    default: return 4; /* fmi3Fatal: a kind this kernel does not know */
    }
}

/* n FMI 3 values of one kind through fmi3Get<type> (kernel.h: get_typed), as doubles. inexact (may
 * be NULL): set to the index of the first 64-bit integer beyond 2^53 in magnitude, which no double
 * holds exactly (*integer: its bits), if *inexact is still negative. */
#define GET_TYPED(T, BEYOND)                                                                         \
    {                                                                                                \
        T x[n];                                                                                      \
        typedef int get_t(void *, const uint32_t *, size_t, T *, size_t);                           \
        st = ((get_t *)c->get_typed[kind])(c->instance, vrs, (size_t)nvr, x, (size_t)n);             \
        for (int32_t i = 0; i < n; i++) {                                                            \
            v[i] = (double)x[i];                                                                     \
            if (inexact && *inexact < 0 && (BEYOND)) *inexact = i, *integer = (uint64_t)x[i];        \
        }                                                                                            \
        break;                                                                                       \
    }
#define EXACT_LIMIT (INT64_C(1) << 53)

/* The ticks counted so far of output clocks vrs (MK_CLOCK_COUNT columns; mk_component.out_clock_ticks). */
static int clock_counts(const mk_component *c, const uint32_t *vrs, int32_t nvr, double *v) {
    for (int32_t i = 0; i < nvr; i++) {
        int32_t o = 0;
        while (o < c->n_out_clocks && c->out_clock_vrs[o] != vrs[i]) o++;
        if (o == c->n_out_clocks) return 4; /* fmi3Fatal: not a counted clock (the tables') */
        v[i] = (double)c->out_clock_ticks[o];
    }
    return 0;
}

static int get_typed(const mk_component *c, int32_t kind, const uint32_t *vrs, int32_t nvr, double *v, int32_t n,
                     int32_t *inexact, uint64_t *integer) {
    int st;
    switch (kind) {
    case MK_FLOAT32: GET_TYPED(float, false)
    case MK_INT8: GET_TYPED(int8_t, false)
    case MK_UINT8: GET_TYPED(uint8_t, false)
    case MK_INT16: GET_TYPED(int16_t, false)
    case MK_UINT16: GET_TYPED(uint16_t, false)
    case MK_UINT32: GET_TYPED(uint32_t, false)
    case MK_INT64: GET_TYPED(int64_t, x[i] > EXACT_LIMIT || x[i] < -EXACT_LIMIT)
    case MK_UINT64: GET_TYPED(uint64_t, x[i] > (uint64_t)EXACT_LIMIT)
    case MK_CLOCK_COUNT: st = clock_counts(c, vrs, nvr, v); break;
    default: st = 4; /* fmi3Fatal: a kind this kernel does not know */
    }
    return st;
}

/* Set n values v (of nvr value references) of one kind through the call of that kind; *call says
 * which call it was. */
static int set_kind(const mk_component *c, int32_t kind, const uint32_t *vrs, int32_t nvr, const double *v,
                    int32_t n, int32_t *call) {
    switch (kind) {
    case MK_REAL_SAMPLE: *call = MK_CALL_SET_REAL; return set_real(c, vrs, nvr, v, n);
    case MK_INTEGER: *call = MK_CALL_SET_INTEGER; return set_discrete(c, kind, vrs, nvr, v, n);
    case MK_BOOLEAN: *call = MK_CALL_SET_BOOLEAN; return set_discrete(c, kind, vrs, nvr, v, n);
    default: *call = TYPED_CALL(MK_CALL_SET_TYPED, kind); return set_typed(c, kind, vrs, nvr, v, n);
    }
}

/* Read n values v (of nvr value references) of one kind through the call of that kind, as
 * get_typed (inexact may be NULL); *call says which call it was. */
static int get_kind(const mk_component *c, int32_t kind, const uint32_t *vrs, int32_t nvr, double *v, int32_t n,
                    int32_t *call, int32_t *inexact, uint64_t *integer) {
    switch (kind) {
    case MK_REAL_SAMPLE: *call = MK_CALL_GET_REAL; return get_real(c, vrs, nvr, v, n);
    case MK_INTEGER: *call = MK_CALL_GET_INTEGER; return get_discrete(c, kind, vrs, nvr, v, n);
    case MK_BOOLEAN: *call = MK_CALL_GET_BOOLEAN; return get_discrete(c, kind, vrs, nvr, v, n);
    default: *call = TYPED_CALL(MK_CALL_GET_TYPED, kind); return get_typed(c, kind, vrs, nvr, v, n, inexact, integer);
    }
}

/* Set the inputs u[0..n_in) (Real, Integer, Boolean, then the typed ones a kind per call in turn;
 * with FMI 3 arrays among them, the calls in_calls); *call says which call failed. */
static int set_inputs(const mk_component *c, const double *u, int32_t *call) {
    const int32_t nr = c->n_in_real, ni = c->n_in_integer, nt = c->n_in_typed, nb = c->n_in - nr - ni - nt;
    int st = STATUS_OK;
    if (c->n_in_calls) {
        for (int32_t g = 0; g < c->n_in_calls; g++) {
            const mk_call *k = &c->in_calls[g];
            int32_t which = 0;
            if ((st = set_kind(c, k->kind, k->vrs, k->n_vrs, u + k->first, k->n_values, &which)) > STATUS_OK)
                return *call = which, st;
        }
        return st;
    }
    if (nr && (st = set_real(c, c->in_vrs, nr, u, nr)) > STATUS_OK) return *call = MK_CALL_SET_REAL, st;
    if (ni && (st = set_discrete(c, MK_INTEGER, c->in_vrs + nr, ni, u + nr, ni)) > STATUS_OK)
        return *call = MK_CALL_SET_INTEGER, st;
    if (nb && (st = set_discrete(c, MK_BOOLEAN, c->in_vrs + nr + ni, nb, u + nr + ni, nb)) > STATUS_OK)
        return *call = MK_CALL_SET_BOOLEAN, st;
    for (int32_t i = c->n_in - nt, end; i < c->n_in; i = end) {
        const int32_t kind = c->in_kinds[i - (c->n_in - nt)];
        for (end = i + 1; end < c->n_in && c->in_kinds[end - (c->n_in - nt)] == kind;) end++;
        if ((st = set_typed(c, kind, c->in_vrs + i, end - i, u + i, end - i)) > STATUS_OK)
            return *call = TYPED_CALL(MK_CALL_SET_TYPED, kind), st;
    }
    return st;
}

/* The outputs through the calls out_calls (FMI 3 arrays among them), as get_outputs. */
static int get_calls(const mk_component *c, double *row, int32_t *call, int32_t *inexact, uint64_t *integer) {
    int st = STATUS_OK;
    *inexact = -1;
    for (int32_t g = 0; g < c->n_out_calls; g++) {
        const mk_call *k = &c->out_calls[g];
        int32_t bad = -1;
        if ((st = get_kind(c, k->kind, k->vrs, k->n_vrs, row + k->first, k->n_values, call, &bad, integer)) > STATUS_OK)
            return st;
        if (bad >= 0) {
            *inexact = k->first + bad;
            break;
        }
    }
    return st;
}

/* Read the outputs into row[0..n_out) (Real, Integer, Boolean, then the typed ones a kind per call
 * in turn); *call says which call failed, *inexact which output is a 64-bit integer beyond 2^53
 * (-1: none; *integer: its bits). */
static int get_outputs(const mk_component *c, double *row, int32_t *call, int32_t *inexact, uint64_t *integer) {
    const int32_t nr = c->n_out_real, ni = c->n_out_integer, nt = c->n_out_typed, nb = c->n_out - nr - ni - nt;
    int st = STATUS_OK;
    if (c->n_out_calls) return get_calls(c, row, call, inexact, integer);
    if (nr && (st = get_real(c, c->out_vrs, nr, row, nr)) > STATUS_OK) return *call = MK_CALL_GET_REAL, st;
    if (ni && (st = get_discrete(c, MK_INTEGER, c->out_vrs + nr, ni, row + nr, ni)) > STATUS_OK)
        return *call = MK_CALL_GET_INTEGER, st;
    if (nb && (st = get_discrete(c, MK_BOOLEAN, c->out_vrs + nr + ni, nb, row + nr + ni, nb)) > STATUS_OK)
        return *call = MK_CALL_GET_BOOLEAN, st;
    *inexact = -1;
    for (int32_t i = c->n_out - nt, end; i < c->n_out; i = end) {
        const int32_t kind = c->out_kinds[i - (c->n_out - nt)];
        int32_t bad = -1;
        for (end = i + 1; end < c->n_out && c->out_kinds[end - (c->n_out - nt)] == kind;) end++;
        if ((st = get_typed(c, kind, c->out_vrs + i, end - i, row + i, end - i, &bad, integer)) > STATUS_OK)
            return *call = TYPED_CALL(MK_CALL_GET_TYPED, kind), st;
        if (bad >= 0) {
            *inexact = i + bad;
            break;
        }
    }
    return st;
}

/* -- String and Binary connections (kernel.h) ------------------------------------------------- */

/* Slot i of sample `sample` in a component's text ring. */
static char *string_slot(const mk_component *c, char *ring, int64_t sample, int32_t i) {
    const size_t n = (size_t)(c->n_out_string + c->n_out_binary);
    return ring + ((size_t)(sample % c->cap) * n + (size_t)i) * MK_STRING_SLOT;
}

static uint64_t text_length(const char *slot) {
    uint64_t n;
    memcpy(&n, slot, sizeof n);
    return n;
}

/* A value of n <= MK_TEXT_MAX bytes into a slot: its length, its bytes, a zero. */
static void put_text(char *slot, const void *data, uint64_t n) {
    memcpy(slot, &n, sizeof n);
    if (n) memcpy(slot + 8, data, (size_t)n);
    slot[8 + n] = 0;
}

static void copy_text(char *to, const char *from) { memcpy(to, from, 8 + (size_t)text_length(from) + 1); }

/* The text inputs vrs[0..n_string + n_binary) from values[i * MK_STRING_SLOT]: n_string Strings
 * through fmi2SetString / fmi3SetString, then n_binary Binaries through fmi3SetBinary; *call says
 * which call failed. */
static int set_texts(const mk_component *c, const uint32_t *vrs, const char *values, int32_t n_string,
                     int32_t n_binary, int32_t *call) {
    int st = STATUS_OK;
    if (n_string) {
        const char *v[n_string];
        for (int32_t i = 0; i < n_string; i++) v[i] = values + (size_t)i * MK_STRING_SLOT + 8;
        st = c->fmi == 3 ? ((fmi3_set_string *)c->set_string)(c->instance, vrs, (size_t)n_string, v, (size_t)n_string)
                         : ((fmi2_set_string *)c->set_string)(c->instance, vrs, (size_t)n_string, v);
        if (st > STATUS_OK) return *call = MK_CALL_SET_STRING, st;
    }
    if (n_binary) {
        const uint8_t *v[n_binary];
        size_t size[n_binary];
        for (int32_t i = 0; i < n_binary; i++) {
            const char *slot = values + (size_t)(n_string + i) * MK_STRING_SLOT;
            v[i] = (const uint8_t *)slot + 8;
            size[i] = (size_t)text_length(slot);
        }
        st = ((fmi3_set_binary *)c->set_binary)(c->instance, vrs + n_string, (size_t)n_binary, size, v, (size_t)n_binary);
        if (st > STATUS_OK) return *call = MK_CALL_SET_BINARY, st;
    }
    return st;
}

/* n values of one text kind (MK_RECORD_STRING or MK_RECORD_BINARY) read into slots[i *
 * MK_STRING_SLOT]: the FMI status, or -1 - i where value i is longer than MK_TEXT_MAX bytes
 * (*length: its length). */
static int get_texts(const mk_component *c, int32_t kind, const uint32_t *vrs, int32_t n, char *slots,
                     uint64_t *length) {
    const void *v[n];
    size_t size[n];
    int st;
    for (int32_t i = 0; i < n; i++) v[i] = NULL, size[i] = 0;
    if (kind == MK_RECORD_BINARY)
        st = ((fmi3_get_binary *)c->get_binary)(c->instance, vrs, (size_t)n, size, (const uint8_t **)v, (size_t)n);
    else
        st = c->fmi == 3 ? ((fmi3_get_string *)c->get_string)(c->instance, vrs, (size_t)n, (const char **)v, (size_t)n)
                         : ((fmi2_get_string *)c->get_string)(c->instance, vrs, (size_t)n, (const char **)v);
    if (st > STATUS_OK) return st;
    for (int32_t i = 0; i < n; i++) {
        uint64_t bytes = kind == MK_RECORD_BINARY ? (uint64_t)size[i] : (v[i] ? strlen(v[i]) : 0);
        if (bytes > MK_TEXT_MAX) return *length = bytes, -1 - i;
        put_text(slots + (size_t)i * MK_STRING_SLOT, v[i] ? v[i] : "", bytes);
    }
    return st;
}

/* Read component ci's text outputs into sample `sample` of `ring`: MK_DONE, MK_FMI_ERROR (the call
 * failed in the step from point j) or MK_TOO_LONG (a value that does not fit its slot). */
static int32_t read_strings(mk_kernel *k, int32_t ci, char *ring, int64_t j, int64_t sample) {
    const mk_component *c = &k->components[ci];
    const int32_t ns = c->n_out_string, nb = c->n_out_binary;
    uint64_t length = 0;
    for (int32_t part = 0; part < 2; part++) {
        const int32_t n = part ? nb : ns, first = part ? ns : 0;
        if (!n) continue;
        int st = get_texts(c, part ? MK_RECORD_BINARY : MK_RECORD_STRING, c->out_string_vrs + first, n,
                           string_slot(c, ring, sample, first), &length);
        if (st < 0) {
            fail(k, MK_TOO_LONG, ci, -1, 0, sample);
            k->error.variable = first - 1 - st;
            k->error.integer = length;
            return MK_TOO_LONG;
        }
        if (st > STATUS_OK)
            return fail(k, MK_FMI_ERROR, ci, part ? MK_CALL_GET_BINARY : MK_CALL_GET_STRING, st, j);
    }
    return MK_DONE;
}

/* The input derivatives of the Real inputs, derivative block by block (one call when every input
 * is Real: the blocks are then contiguous). */
static int set_derivatives(const mk_component *c, const double *u) {
    const int32_t nr = c->n_in_real, nd = c->n_blocks - c->n_values;
    const double *d = u + (size_t)c->n_values * c->n_in;
    if (nr == c->n_in)
        return ((fmi2_set_derivatives *)c->set_derivatives)(c->instance, c->derivative_vrs, (size_t)c->n_derivatives,
                                                            c->derivative_orders, d);
    for (int32_t b = 0; b < nd; b++) {
        int st = ((fmi2_set_derivatives *)c->set_derivatives)(
            c->instance, c->derivative_vrs + (size_t)b * nr, (size_t)nr, c->derivative_orders + (size_t)b * nr,
            d + (size_t)b * c->n_in);
        if (st > STATUS_OK) return st;
    }
    return STATUS_OK;
}

/* doStep. *terminate: 1 when an FMI 3 FMU completed the step and asks to end the simulation,
 * 2 when an FMI 2 FMU discarded it to end the simulation (fmi2Discard with fmi2Terminated: its
 * outputs are not those of the step's end). final: no state from before t will be restored
 * (false during start-up, whose sweeps restore a saved state). */
static int do_step(const mk_component *c, double t, bool final, int *terminate) {
    if (c->fmi == 3) {
        bool event = false, early = false, end = false;
        double last = t;
        int st = ((fmi3_do_step *)c->do_step)(c->instance, t, c->h, final, &event, &end, &early, &last);
        *terminate = end ? 1 : 0;
        return st;
    }
    /* FMI 1.0 newStep: always true, since a step is repeated only from a restored state, which FMI 1
     * cannot save (the plan gives it no start-up sweeps); it has no fmi2Terminated to ask after a
     * discard either: fmiDiscard is a failure */
    if (c->fmi == 1) return ((fmi1_do_step *)c->do_step)(c->instance, t, c->h, 1);
    int st = ((fmi2_do_step *)c->do_step)(c->instance, t, c->h, final ? 1 : 0);
    int32_t ended = 0;
    if (st == FMI2_DISCARD && c->get_boolean_status &&
        ((fmi2_get_boolean_status *)c->get_boolean_status)(c->instance, FMI2_TERMINATED, &ended) <= STATUS_OK &&
        ended) {
        *terminate = 2;
        return STATUS_OK;
    }
    return st;
}

/* do_step of a component whose FMU asks for its inputs inside the step (FMI 3 intermediate update):
 * its environment pointed at the step's input blocks u and point t for the while; a failure of
 * doStep (*call MK_CALL_DO_STEP) or else of a set inside it (MK_CALL_SET_REAL). */
static int intermediate_step(mk_component *c, const double *u, double t, bool final, int *terminate,
                             int32_t *call) {
    mk_intermediate *iu = c->intermediate;
    iu->component = c, iu->u = u, iu->t0 = t, iu->status = 0;
    int st = do_step(c, t, final, terminate);
    iu->u = NULL;
    *call = st > STATUS_OK ? MK_CALL_DO_STEP : MK_CALL_SET_REAL;
    return st > STATUS_OK ? st : iu->status;
}

/* A recorded value into its row's 8 bytes as `how` says (kernel.h: MK_STORE_*). */
static void store(double *to, int32_t how, double value) {
    if (how == MK_STORE_INT64) {
        int64_t v = (int64_t)value;
        memcpy(to, &v, sizeof v);
    } else if (how == MK_STORE_UINT64) {
        uint64_t v = (uint64_t)value;
        memcpy(to, &v, sizeof v);
    } else
        *to = value;
}

/* One recorded value of any kind but MK_REAL_SAMPLE into its row's 8 bytes as `how` says: an Int64
 * or UInt64 stored as such is exact whatever its magnitude; *call says which call it was. */
static int get_scalar(const mk_component *c, int32_t kind, int32_t how, uint32_t vr, double *out, int32_t *call) {
    if (how == MK_STORE_DOUBLE) return get_kind(c, kind, &vr, 1, out, 1, call, NULL, NULL);
    typedef int get_t(void *, const uint32_t *, size_t, void *, size_t); /* the bits, through its own call */
    uint64_t v = 0;
    *call = TYPED_CALL(MK_CALL_GET_TYPED, kind);
    int status = ((get_t *)c->get_typed[kind])(c->instance, &vr, 1, &v, 1);
    memcpy(out, &v, sizeof v);
    return status;
}

/* -- inputs ---------------------------------------------------------------------------------- */

/* np.interp(t, times, values) of one point, in numpy's arithmetic. */
static double interp(const mk_stimulus *s, double t) {
    const double *x = s->times, *y = s->values;
    int32_t n = s->n;
    if (isnan(t)) return t;
    if (t < x[0]) return y[0];
    if (t > x[n - 1]) return y[n - 1];
    int32_t lo = 0, hi = n - 1; /* x[lo] <= t, last such index */
    while (lo < hi) {
        int32_t mid = lo + (hi - lo + 1) / 2;
        if (x[mid] <= t) lo = mid;
        else hi = mid - 1;
    }
    if (lo == n - 1 || x[lo] == t) return y[lo];
    double slope = (y[lo + 1] - y[lo]) / (x[lo + 1] - x[lo]);
    double v = slope * (t - x[lo]) + y[lo];
    if (isnan(v)) {
        v = slope * (t - x[lo + 1]) + y[lo + 1];
        if (isnan(v) && y[lo] == y[lo + 1]) v = y[lo];
    }
    return v;
}

static double stimulus_value(const mk_stimulus *s, double t) {
    if (s->kind == 1) return interp(s, t);
    if (t < s->times[0]) return s->start_value;
    int32_t lo = 0, hi = s->n - 1; /* last i with times[i] <= t */
    while (lo < hi) {
        int32_t mid = lo + (hi - lo + 1) / 2;
        if (s->times[mid] <= t) lo = mid;
        else hi = mid - 1;
    }
    return s->values[lo];
}

/* -- transformations (kernel.h: mk_transform) ------------------------------------------------- */

static double transform_value(const mk_transform *t, double v) {
    if (t->kind == MK_TRANSFORM_LINEAR) return t->factor * v + t->offset;
    if (t->kind == MK_TRANSFORM_MAP)
        for (int32_t e = 0; e < t->n_map; e++)
            if (t->from[e] == v) return t->to[e];
    return v;
}

/* The values v[0..n_cols) of link lk's columns, transformed in place. */
static void transform_values(const mk_link *lk, double *v) {
    for (int32_t i = 0; i < lk->n_cols; i++) v[i] = transform_value(&lk->transform[i], v[i]);
}

/* Link lk's inputs of every step and block in u, transformed in place: the value blocks as values, the
 * derivative blocks scaled by a linear transformation's factor (its offset is constant). */
static void transform_inputs(const mk_component *c, const mk_link *lk) {
    const int32_t nb = c->n_blocks;
    for (int32_t m = 0; m < c->step_ratio; m++)
        for (int32_t b = 0; b < nb; b++) {
            double *v = c->u + ((size_t)m * nb + b) * c->n_in + lk->slot0;
            if (b < c->n_values) transform_values(lk, v);
            else
                for (int32_t i = 0; i < lk->n_cols; i++)
                    if (lk->transform[i].kind == MK_TRANSFORM_LINEAR) v[i] *= lk->transform[i].factor;
        }
}

/* The coupling error estimate of link lk (see kernel.h) at the start of plain macro step n: the
 * prediction made in macro step n - 1 against sample n k_source, which exists now; then the
 * prediction of sample (n + 1) k_source from this macro step's window (still protected: the
 * consumer has not yet released it). */
static void estimate(const mk_link *lk, const double *hist, int64_t cap, int64_t n_out, int64_t n) {
    const int64_t base = n * lk->k_source;
    const double *now = hist + (base % cap) * n_out;
    for (int32_t i = 0; i < lk->n_cols; i++) {
        double y = now[lk->columns[i]], *e = lk->error + MK_ERROR_FIELDS * i;
        if (n > lk->n_plain) { /* a full-order prediction was made in macro step n - 1 */
            double d = fabs(lk->predicted[i] - y);
            if (!(d <= e[0])) e[0] = d;
            e[1] += d * d;
            e[2] += 1.0;
            e[5] = d;
        }
        if (y < e[3]) e[3] = y;
        if (y > e[4]) e[4] = y;
        double acc = lk->predict[0] * y;
        for (int32_t q = 1; q < lk->terms; q++) acc += lk->predict[q] * hist[((base - q) % cap) * n_out + lk->columns[i]];
        lk->predicted[i] = acc;
    }
}

/* When a held input's sample in a step is of, for a component in FMI 3 event mode (mk_component.cs_late):
 * the step's start or earlier, a time in the step, a later one. */
enum { CS_AT_START = 0, CS_IN_STEP = 1, CS_AFTER_STEP = 2 };

/* u for macro step n: every link's polynomials (from the live or the previous sweep's histories),
 * then the stimuli; for a component in FMI 3 event mode the time of each held input's sample. */
static void fill_inputs(const mk_kernel *k, mk_component *c, int64_t n, bool relaxed) {
    const int32_t kc = c->step_ratio, nb = c->n_blocks, n_in = c->n_in;
    for (int32_t l = 0; l < c->n_links; l++) {
        const mk_link *lk = &c->links[l];
        const mk_component *src = &k->components[lk->source];
        const bool previous = relaxed && !(lk->ahead && k->iterate); /* Gauss-Seidel sweeps: current */
        const double *hist = previous ? src->hist_previous : src->hist;
        const int64_t cap = src->cap, n_out = src->n_out, base = n * lk->k_source;
        if (lk->predict && !relaxed && n >= lk->n_plain) estimate(lk, hist, cap, n_out, n);
        int32_t t = relaxed ? lk->n_plain + 1 + (n < lk->n_relaxed ? (int32_t)n : lk->n_relaxed)
                            : (n < lk->n_plain ? (int32_t)n : lk->n_plain);
        const int64_t *off = lk->offsets + (size_t)t * lk->terms * kc;
        const double *w = lk->weights + (size_t)t * nb * lk->terms * kc;
        const uint8_t *zero = lk->zero + (size_t)t * nb * kc;
        for (int32_t m = 0; m < kc; m++) {
            for (int32_t b = 0; b < nb; b++) {
                double *out = c->u + ((size_t)m * nb + b) * n_in + lk->slot0;
                if (zero[b * kc + m]) {
                    for (int32_t i = 0; i < lk->n_cols; i++) out[i] = 0.0;
                    continue;
                }
                const double *wb = w + (size_t)b * lk->terms * kc;
                for (int32_t i = 0; i < lk->n_cols; i++) {
                    const int64_t col = lk->columns[i];
                    double acc = wb[m] * hist[((base + off[m]) % cap) * n_out + col];
                    for (int32_t q = 1; q < lk->terms; q++)
                        acc += wb[q * kc + m] * hist[((base + off[q * kc + m]) % cap) * n_out + col];
                    out[i] = b < c->n_values ? acc : acc / lk->scale[b];
                }
            }
        }
        if (lk->transform) transform_inputs(c, lk);
        for (int32_t m = 0; c->cs_events && m < kc; m++) { /* the time of a held input's sample, s ks / H */
            const int64_t s = (base + off[m]) * kc, j = n * kc + m;
            const uint8_t when = s <= j * lk->k_source ? CS_AT_START : s <= (j + 1) * lk->k_source ? CS_IN_STEP
                                                                                                 : CS_AFTER_STEP;
            for (int32_t i = 0; i < lk->n_cols; i++) c->cs_late[(size_t)m * n_in + lk->slot0 + i] = when;
        }
    }
    /* String and Binary links: the held sample of each step, copied (the source may overwrite its
     * slot once this component has taken its inputs, before the step sets them) */
    const size_t n_text_in = (size_t)(c->n_in_string + c->n_in_binary);
    for (int32_t l = 0; l < c->n_string_links; l++) {
        const mk_link *lk = &c->string_links[l];
        const mk_component *src = &k->components[lk->source];
        char *ring = relaxed && !(lk->ahead && k->iterate) ? src->strings_previous : src->strings;
        int32_t t = relaxed ? lk->n_plain + 1 + (n < lk->n_relaxed ? (int32_t)n : lk->n_relaxed)
                            : (n < lk->n_plain ? (int32_t)n : lk->n_plain);
        const int64_t *off = lk->offsets + (size_t)t * kc; /* one term */
        const int64_t base = n * lk->k_source;
        for (int32_t m = 0; m < kc; m++) {
            char *to = c->string_u + ((size_t)m * n_text_in + lk->slot0) * MK_STRING_SLOT;
            for (int32_t i = 0; i < lk->n_cols; i++)
                copy_text(to + (size_t)i * MK_STRING_SLOT, string_slot(src, ring, base + off[m], lk->columns[i]));
        }
    }
    if (c->n_stimuli) {
        const int64_t j0 = n * kc;
        for (int32_t m = 0; m < kc; m++)
            for (int32_t b = 0; b < c->n_values; b++) {
                double t = point_time(c, j0 + m + b);
                double *row = c->u + ((size_t)m * nb + b) * n_in;
                for (int32_t s = 0; s < c->n_stimuli; s++)
                    row[c->stimuli[s].slot] = stimulus_value(&c->stimuli[s], t);
            }
    }
}

/* -- stepping -------------------------------------------------------------------------------- */

/* Read component ci's outputs into `row`, its sample at point `sample`: MK_DONE, MK_FMI_ERROR (a call
 * failed in the step from point j) or MK_INEXACT (a 64-bit integer beyond 2^53 in magnitude, which
 * a connection would round). */
static int32_t read_outputs(mk_kernel *k, int32_t ci, double *row, int64_t j, int64_t sample) {
    int32_t call = 0, bad = -1;
    uint64_t integer = 0;
    int st = get_outputs(&k->components[ci], row, &call, &bad, &integer);
    if (st > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, call, st, j);
    if (bad >= 0) {
        fail(k, MK_INEXACT, ci, -1, 0, sample);
        k->error.variable = bad;
        k->error.value = row[bad];
        k->error.integer = integer;
        return MK_INEXACT;
    }
    return MK_DONE;
}

/* MK_NOT_FINITE / MK_DIVERGED if sample j (in `row`) is not finite or beyond its bound. */
static int32_t check_sample(mk_kernel *k, int32_t ci, const double *row, int64_t j) {
    const mk_component *c = &k->components[ci];
    for (int32_t o = 0; o < c->n_out; o++)
        if (!isfinite(row[o])) {
            fail(k, MK_NOT_FINITE, ci, -1, 0, j);
            k->error.variable = o;
            k->error.value = row[o];
            return MK_NOT_FINITE;
        }
    for (int32_t o = 0; o < c->n_out; o++)
        if (fabs(row[o]) > c->bound[o]) {
            fail(k, MK_DIVERGED, ci, -1, 0, j);
            k->error.variable = o;
            k->error.value = row[o];
            return MK_DIVERGED;
        }
    return MK_DONE;
}

/* Before component ci fills its inputs of macro step n: its sources' samples exist. */
static int32_t wait_inputs(mk_kernel *k, const mk_component *c, int64_t n) {
    for (int32_t l = 0; l < c->n_links + c->n_string_links; l++) {
        const mk_link *lk = l < c->n_links ? &c->links[l] : &c->string_links[l - c->n_links];
        /* a source that goes first: its sample at the macro step's end as stepped (resampling it
         * needs this component's own step) */
        mk_counter *ready = lk->ahead ? &k->shared->stepped[lk->source] : &k->shared->published[lk->source];
        if (wait_for(k, ready, n + lk->ahead)) return aborted(k);
    }
    return MK_DONE;
}

/* Before component ci writes macro step n into its ring: every consumer has taken its inputs of
 * macro step n - 1, the last that reads samples this step overwrites (history_capacity). */
static int32_t wait_ring(mk_kernel *k, const mk_component *c, int64_t n) {
    for (int32_t i = 0; i < c->n_consumers; i++)
        if (wait_for(k, &k->shared->consumed[c->consumers[i]], n)) return aborted(k);
    return MK_DONE;
}

/* What this worker is doing, for the supervisor's hang detection: the component whose FMU calls
 * began at busy[0] (CLOCK_MONOTONIC ns), or 0 while it waits for peers or the clock. */
static void mark_busy(mk_kernel *k, int32_t ci) {
    if (!k->shared) return;
    k->shared->busy[1] = ci;
    __atomic_store_n(&k->shared->busy[0], now_ns(), __ATOMIC_RELEASE);
}

static void mark_idle(mk_kernel *k) {
    if (k->shared) __atomic_store_n(&k->shared->busy[0], 0, __ATOMIC_RELEASE);
}

/* -- Model Exchange components (kernel.h: mk_component.me) ----------------------------------------- */

static int get_directional_derivative(const mk_component *c, const uint32_t *unknowns, size_t n_unknowns,
                                      const uint32_t *known, const double *seed, double *out);

/* Real input i of a step with input blocks u, dt after its communication point: its polynomial
 * u0 + d1 dt + d2 dt^2 / 2 + d3 dt^3 / 6 in the arithmetic of an FMU that interpolates its inputs
 * (fmus/fmi/step.c), so that every way of handing the polynomial over gives the same bits. */
static double input_at(const mk_component *c, const double *u, int32_t i, double dt) {
    const int32_t nd = c->n_blocks - c->n_values, n_in = c->n_in;
    const double *d = u + (size_t)c->n_values * n_in;
    double d1 = nd > 0 ? d[i] : 0.0, d2 = nd > 1 ? d[n_in + i] : 0.0, d3 = nd > 2 ? d[2 * n_in + i] : 0.0;
    return u[i] + dt * (d1 + dt * (d2 / 2.0 + dt * d3 / 6.0));
}

/* -- FMI 3 intermediate update (kernel.h mk_intermediate) ------------------------------------------ */

void mk_intermediate_update(void *environment, double time, bool set_requested, bool get_allowed,
                            bool step_finished, bool can_return_early, bool *early_return_requested,
                            double *early_return_time) {
    mk_intermediate *iu = environment;
    (void)get_allowed, (void)step_finished, (void)can_return_early, (void)early_return_time;
    if (early_return_requested) *early_return_requested = false;
    if (!iu || !iu->u || !set_requested || iu->n == 0) return; /* outside the kernel's doStep: held */
    const mk_component *c = iu->component;
    for (int32_t i = 0; i < iu->n; i++) iu->values[i] = input_at(c, iu->u, iu->slots[i], time - iu->t0);
    int st = ((fmi3_set_float64 *)c->set_real)(c->instance, iu->vrs, (size_t)iu->n, iu->values, (size_t)iu->n);
    if (st > iu->status) iu->status = st;
    iu->calls++;
}

/* What the solver's right-hand side of an ME component needs: the communication step's input blocks
 * and point, and the failing call. */
typedef struct {
    mk_component *c;
    const double *u;
    double t0;
    int32_t call;
    int status;
    bool final; /* fmi2/3CompletedIntegratorStep's noSetFMUStatePriorToCurrentPoint */
} me_context;

/* The Real inputs at time t from the step's polynomials, in the arithmetic of an FMU that
 * interpolates its inputs (fmus/fmi/step.c), set; held inputs stay as set_inputs left them. */
static int me_set_inputs(me_context *m, double t) {
    mk_component *c = m->c;
    if (c->n_blocks == c->n_values || c->n_in_real == 0) return STATUS_OK;
    for (int32_t i = 0; i < c->n_in_real; i++) c->scratch[i] = input_at(c, m->u, i, t - m->t0);
    m->call = MK_CALL_SET_REAL;
    return set_real(c, c->in_vrs, c->n_in_real, c->scratch, c->n_in_real);
}

/* The FMU at time t with states x and the inputs of time t. */
static int me_set_point(me_context *m, double t, const double *x) {
    mk_component *c = m->c;
    m->call = MK_CALL_SET_TIME;
    if ((m->status = ((fmi_set_time *)c->set_time)(c->instance, t)) > STATUS_OK) return 1;
    if ((m->status = me_set_inputs(m, t)) > STATUS_OK) return 1;
    m->call = MK_CALL_SET_STATES;
    if (c->n_states && (m->status = ((fmi_set_states *)c->set_states)(c->instance, x, (size_t)c->n_states)) > STATUS_OK)
        return 1;
    return 0;
}

/* RhsFn: dx = f(t, x) from fmi2GetDerivatives / fmi3GetContinuousStateDerivatives. */
static int me_rhs(void *ctx, double t, const double *x, double *dx) {
    me_context *m = ctx;
    if (me_set_point(m, t, x)) return 1;
    m->call = MK_CALL_GET_DERIVATIVES;
    m->status = ((fmi_get_states *)m->c->get_derivatives)(m->c->instance, dx, (size_t)m->c->n_states);
    return m->status > STATUS_OK;
}

/* JacFn: df/dx at (t, x), a column per state from directional derivatives of the derivatives. */
static int me_jacobian(void *ctx, double t, const double *x, double *J) {
    me_context *m = ctx;
    mk_component *c = m->c;
    const int32_t n = c->n_states;
    double column[n];
    if (!c->me_state_vrs) return solver_fd_jacobian(c->me_work, n, me_rhs, m, t, x);
    if (me_set_point(m, t, x)) return 1;
    m->call = MK_CALL_DIRECTIONAL_DERIVATIVE;
    for (int32_t j = 0; j < n; j++) {
        const double seed = 1.0;
        m->status = get_directional_derivative(c, c->me_derivative_vrs, (size_t)n, &c->me_state_vrs[j], &seed, column);
        if (m->status > STATUS_OK) { /* not this FMU's after all: finite differences from now on (J is the
                                        work's matrix, f(t, x) evaluated: solver_fd_jacobian's contract) */
            c->me_state_vrs = NULL;
            return solver_fd_jacobian(c->me_work, n, me_rhs, m, t, x);
        }
        for (int32_t i = 0; i < n; i++) J[i * n + j] = column[i];
    }
    return 0;
}

/* fmi2/3CompletedIntegratorStep at time t with states x: *event, *terminate as the FMU says. */
static int me_completed(me_context *m, double t, const double *x, bool final, bool *event, bool *terminate) {
    mk_component *c = m->c;
    if (me_set_point(m, t, x)) return m->status;
    m->call = MK_CALL_COMPLETED_STEP;
    if (c->fmi == 3) return ((fmi3_completed_step *)c->completed_step)(c->instance, final, event, terminate);
    int32_t e = 0, end = 0;
    int st = ((fmi2_completed_step *)c->completed_step)(c->instance, final ? 1 : 0, &e, &end);
    *event = e != 0;
    *terminate = end != 0;
    return st;
}

/* IndicatorFn: z = the FMU's event indicators at (t, x), fmi2/3GetEventIndicators. */
static int me_indicators(void *ctx, double t, const double *x, double *z) {
    me_context *m = ctx;
    if (me_set_point(m, t, x)) return 1;
    m->call = MK_CALL_GET_EVENT_INDICATORS;
    m->status = ((fmi_get_states *)m->c->get_event_indicators)(m->c->instance, z, (size_t)m->c->n_event_indicators);
    return m->status > STATUS_OK;
}

/* CompletedFn: fmi2/3CompletedIntegratorStep, a step event and the end as the FMU asks. */
static int me_step_done(void *ctx, double t, const double *x, int *event, int *stop) {
    me_context *m = ctx;
    bool e = false, end = false;
    if ((m->status = me_completed(m, t, x, m->final, &e, &end)) > STATUS_OK) return 1;
    *event = e, *stop = end;
    return 0;
}

#define MK_EVENT_ROUNDS 1000 /* an event iteration longer than this never ends (MK_EVENT) */
#define MK_EARLY_RETURNS 1000000 /* FMI 3 event mode: early returns in one communication step (MK_EVENT) */
#define MK_NEVER_ENDS (-1)   /* me_context.status of such an iteration */

/* The event iteration of an FMU in event mode (new discrete states until none are needed, or the FMU
 * ends the simulation: *stop, the FMU left in event mode), then continuous-time mode and the states
 * read back into x if they changed (*changed); *next_time the FMU's next time event. */
static int me_iterate(me_context *m, double *x, double *next_time, int *stop, bool *changed) {
    mk_component *c = m->c;
    bool needed = true;
    *changed = false;
    m->call = MK_CALL_UPDATE_DISCRETE_STATES;
    for (int round = 0; needed; round++) {
        bool end = false, values = false, defined = false;
        double when = 0.0;
        if (round == MK_EVENT_ROUNDS) return m->status = MK_NEVER_ENDS, 1;
        if (c->fmi == 3) {
            bool nominals = false;
            m->status = ((fmi3_update_discrete_states *)c->update_discrete_states)(c->instance, &needed, &end, &nominals,
                                                                                   &values, &defined, &when);
        } else {
            fmi2_event_info info = {0, 0, 0, 0, 0, 0.0};
            m->status = ((fmi2_new_discrete_states *)c->update_discrete_states)(c->instance, &info);
            needed = info.new_discrete_states_needed != 0, end = info.terminate_simulation != 0;
            values = info.values_changed != 0, defined = info.next_event_time_defined != 0;
            when = info.next_event_time;
        }
        if (m->status > STATUS_OK) return 1;
        *changed |= values;
        *next_time = defined ? when : INFINITY;
        if (end) return *stop = 1, 0;
    }
    m->call = MK_CALL_ENTER_CONTINUOUS_TIME_MODE;
    if ((m->status = ((fmi_mode *)c->enter_continuous_time_mode)(c->instance)) > STATUS_OK) return 1;
    m->call = MK_CALL_GET_STATES;
    if (*changed && c->n_states && (m->status = ((fmi_get_states *)c->get_states)(c->instance, x, (size_t)c->n_states)) > STATUS_OK)
        return 1;
    return 0;
}

/* EventFn: the event at (t, x): event mode, the event iteration, continuous-time mode. */
static int me_event(void *ctx, double t, double *x, double *next_time, int *stop) {
    me_context *m = ctx;
    mk_component *c = m->c;
    bool changed = false;
    if (me_set_point(m, t, x)) return 1;
    m->call = MK_CALL_ENTER_EVENT_MODE;
    if ((m->status = ((fmi_mode *)c->enter_event_mode)(c->instance)) > STATUS_OK) return 1;
    if (me_iterate(m, x, next_time, stop, &changed)) return 1;
    (*c->me_event_count)++;
    return 0;
}

/* An FMU that rests in event mode between its communication steps (me_input_events), its inputs of
 * time t set: the event iteration there (an input event), continuous-time mode; the history restarted
 * if the states changed. 1 (m's call and status) if a call failed. */
static int me_input_event(me_context *m, double t, int *stop) {
    mk_component *c = m->c;
    bool changed = false;
    m->call = MK_CALL_SET_TIME;
    if ((m->status = ((fmi_set_time *)c->set_time)(c->instance, t)) > STATUS_OK) return 1;
    if (me_iterate(m, c->me_x, &c->me_next_event, stop, &changed)) return 1;
    if (changed) solver_reset(c->me_memory, c->n_states);
    return 0;
}

/* One communication step of ME component ci from point j (time t), inputs u: its states integrated
 * to t + h by me_substeps steps of its solver (the substep times from the integer s, as the
 * project's FMUs take theirs) with the FMU's events (fmus/solvers/events.c ode_advance: a time
 * event cuts the step, a state event is located, a step event handled, each followed by the event
 * iteration and a restarted history), the FMU left at t + h with the step-start inputs. *terminate:
 * 1 when the FMU asks to end the simulation. A directional derivative that fails makes the Jacobian
 * finite differences from then on (as the loops'). */
static int32_t me_step(mk_kernel *k, int32_t ci, const double *u, double t, int64_t j, bool final, int *terminate) {
    mk_component *c = &k->components[ci];
    me_context m = {c, u, t, MK_CALL_GET_STATES, STATUS_OK, final};
    const int32_t n = c->n_states, steps = c->me_substeps;
    const double h = c->h / (double)steps;
    int stop = 0;
    if (c->me_input_events && me_input_event(&m, t, &stop))
        return fail(k, m.status == MK_NEVER_ENDS ? MK_EVENT : MK_FMI_ERROR, ci, m.call, m.status, j);
    if (stop) return *terminate = 1, MK_DONE; /* ended at the input event, in event mode */
    m.call = MK_CALL_GET_STATES;
    if (n && (m.status = ((fmi_get_states *)c->get_states)(c->instance, c->me_x, (size_t)n)) > STATUS_OK)
        return fail(k, MK_FMI_ERROR, ci, m.call, m.status, j);
    const OdeProblem problem = {(SolverKind)c->me_solver,
                                c->me_memory,
                                c->me_work,
                                n,
                                c->n_event_indicators,
                                me_rhs,
                                c->me_state_vrs ? me_jacobian : NULL,
                                c->n_event_indicators ? me_indicators : NULL,
                                me_step_done,
                                me_event,
                                &m,
                                c->me_tolerance};
    long long events = 0;
    int rc = ode_advance(&problem, c->me_events, t, h, steps, t + c->h, c->me_x, &c->me_next_event, &events);
    if (rc == ODE_STOP) *terminate = 1;
    else if (rc == 1) return fail(k, m.status == MK_NEVER_ENDS ? MK_EVENT : MK_FMI_ERROR, ci, m.call, m.status, j);
    else if (rc != 0) return fail(k, MK_FMI_ERROR, ci, MK_CALL_SOLVER, rc, j);
    m.call = MK_CALL_ENTER_EVENT_MODE; /* at t + h: its inputs are set and its outputs read there */
    if (c->me_input_events && rc == 0 && (m.status = ((fmi_mode *)c->enter_event_mode)(c->instance)) > STATUS_OK)
        return fail(k, MK_FMI_ERROR, ci, m.call, m.status, j);
    /* the step-start inputs again, as an interpolating FMU has them after its step */
    if (c->n_blocks > c->n_values && c->n_in_real && (m.status = set_real(c, c->in_vrs, c->n_in_real, u, c->n_in_real)) > STATUS_OK)
        return fail(k, MK_FMI_ERROR, ci, MK_CALL_SET_REAL, m.status, j);
    return MK_DONE;
}

/* Start-up: an ME component's multistep history, an FMI 3 event-mode component's discrete inputs as set,
 * saved with its FMU state (save) or restored. */
static void me_history(mk_component *c, bool save) {
    const size_t held = sizeof(double) * (size_t)c->n_cs_held; /* FMI 3 event mode: the discrete inputs set */
    if (held) save ? memcpy(c->cs_held_saved, c->cs_held, held) : memcpy(c->cs_held, c->cs_held_saved, held);
    if (!c->me) return;
    const size_t size = sizeof(double) * solver_memory_size(c->n_states);
    if (save) memcpy(c->me_memory_saved, c->me_memory, size), c->me_next_event_saved = c->me_next_event;
    else memcpy(c->me_memory, c->me_memory_saved, size), c->me_next_event = c->me_next_event_saved;
}

#include "scheduled.c" /* Scheduled Execution components: se_step, mk_scheduled_start */

/* -- FMI 3 Co-Simulation event mode (kernel.h: mk_component.cs_events) ------------------------------- */

/* Whether input slot i is discrete: an FMI 3 FMU in event mode takes a change of it in event mode only. */
static bool discrete_input(const mk_component *c, int32_t i) {
    const int32_t typed = c->n_in - c->n_in_typed;
    return i >= c->n_in_real && (i < typed || c->in_kinds[i - typed] != MK_FLOAT32);
}

/* Whether a discrete input of step m's inputs u whose sample is of time `when` (CS_*) differs from the
 * value last set. */
static bool discrete_changed(const mk_component *c, const double *u, int32_t m, uint8_t when) {
    const uint8_t *late = c->cs_late + (size_t)m * c->n_in;
    for (int32_t i = c->n_in_real, d = 0; i < c->n_in; i++) {
        if (!discrete_input(c, i)) continue;
        if (late[i] == when && u[i] != c->cs_held[d]) return true;
        d++;
    }
    return false;
}

static void hold_discrete(mk_component *c, const double *u) {
    for (int32_t i = c->n_in_real, d = 0; i < c->n_in; i++)
        if (discrete_input(c, i)) c->cs_held[d++] = u[i];
}

/* Step m's inputs u (a block of them) with the discrete ones whose sample is of time `from` (CS_*) or
 * later as last set, into c->scratch. */
static const double *held_from(mk_component *c, const double *u, int32_t m, uint8_t from) {
    const uint8_t *late = c->cs_late + (size_t)m * c->n_in;
    memcpy(c->scratch, u, sizeof(double) * (size_t)c->n_in);
    for (int32_t i = c->n_in_real, d = 0; i < c->n_in; i++) {
        if (!discrete_input(c, i)) continue;
        if (late[i] >= from) c->scratch[i] = c->cs_held[d];
        d++;
    }
    return c->scratch;
}

typedef int fmi3_set_clock(void *, const uint32_t *, size_t, const bool *);

/* An input event's linked input clocks (MK_CLOCK_COUNT inputs of u) whose source's count differs
 * from the one last set: set active (fmi3SetClock), before the discrete-state updates. */
static int set_clocks(const mk_component *c, const double *u) {
    const int32_t typed = c->n_in - c->n_in_typed;
    const bool active = true;
    for (int32_t i = c->n_in_real, d = 0; i < c->n_in; i++) {
        if (!discrete_input(c, i)) continue;
        int st;
        if (i >= typed && c->in_kinds[i - typed] == MK_CLOCK_COUNT && u[i] != c->cs_held[d] &&
            (st = ((fmi3_set_clock *)c->set_clock)(c->instance, &c->in_vrs[i], 1, &active)) > STATUS_OK)
            return st;
        d++;
    }
    return 0;
}

/* The event iteration of an FMI 3 Co-Simulation FMU at its current time (point j's step): event mode,
 * its inputs u set there where given (an input event; NULL: those of the step, held), then
 * fmi3UpdateDiscreteStates until no update is needed (at most MK_EVENT_ROUNDS, else MK_EVENT), step
 * mode. *terminate: 1 when the FMU ends the simulation (left in event mode). */
static int32_t cs_event(mk_kernel *k, int32_t ci, const double *u, int64_t j, int *terminate) {
    mk_component *c = &k->components[ci];
    int32_t call = MK_CALL_ENTER_EVENT_MODE;
    int st = ((fmi_mode *)c->enter_event_mode)(c->instance);
    if (st > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, call, st, j);
    if (u && (st = set_inputs(c, u, &call)) > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, call, st, j);
    if (u && c->set_clock && (st = set_clocks(c, u)) > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, MK_CALL_SET_CLOCK, st, j);
    if (u) hold_discrete(c, u);
    bool needed = true, end = false;
    for (int32_t round = 0; needed; round++) {
        bool nominals = false, values = false, defined = false;
        double when = 0.0;
        if (round == MK_EVENT_ROUNDS) return fail(k, MK_EVENT, ci, MK_CALL_UPDATE_DISCRETE_STATES, 0, j);
        st = ((fmi3_update_discrete_states *)c->update_discrete_states)(c->instance, &needed, &end, &nominals, &values,
                                                                       &defined, &when);
        if (st > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, MK_CALL_UPDATE_DISCRETE_STATES, st, j);
        if (end) return *terminate = 1, MK_DONE;
    }
    (*c->me_event_count)++;
    int32_t code = count_clocks(k, ci, j);
    if (code != MK_DONE) return code;
    st = ((fmi_mode *)c->enter_step_mode)(c->instance);
    return st > STATUS_OK ? fail(k, MK_FMI_ERROR, ci, MK_CALL_ENTER_STEP_MODE, st, j) : MK_DONE;
}

/* fmi3DoStep of an FMU in event mode from point j (time t) to t + h: at an event it reports, the event
 * iteration at once (its outputs at t + h are those after the event); where it returned early (a time,
 * state or step event inside the step), the rest of the step after it, its inputs held, so that its
 * communication points stay those of the schedule. *terminate: 1 when it ends the simulation. */
static int32_t cs_step(mk_kernel *k, int32_t ci, const double *u, double t, int64_t j, bool final,
                       int *terminate) {
    mk_component *c = &k->components[ci];
    mk_intermediate *iu = c->intermediate; /* asks for its inputs inside the step: u's polynomials from t */
    const double end = t + c->h;
    double from = t;
    for (int64_t events = 0;; events++) {
        bool event = false, early = false, stop = false;
        double last = end;
        if (events == MK_EARLY_RETURNS) /* events without end inside one step (a Zeno point) */
            return fail(k, MK_EVENT, ci, MK_CALL_DO_STEP, 0, j);
        const double size = events ? end - from : c->h; /* (the FMU ends the rest at its step's end) */
        if (iu) iu->component = c, iu->u = u, iu->t0 = t, iu->status = 0;
        int st = ((fmi3_do_step *)c->do_step)(c->instance, from, size, final, &event, &stop, &early, &last);
        if (iu) iu->u = NULL;
        if (st > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, MK_CALL_DO_STEP, st, j);
        if (iu && iu->status > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, MK_CALL_SET_REAL, iu->status, j);
        if (stop) return *terminate = 1, MK_DONE;
        int32_t code = event ? cs_event(k, ci, NULL, j, terminate) : MK_DONE;
        if (code != MK_DONE || *terminate || !early || !(last < end)) return code;
        from = last; /* returned early (at an event, or as the importer asked): the rest of the step */
    }
}

/* The `ratio` communication steps of component ci in macro step n, inputs from u. */
static int32_t communication_steps(mk_kernel *k, int32_t ci, int64_t n) {
    mk_component *c = &k->components[ci];
    const int32_t kc = c->step_ratio, nb = c->n_blocks, n_in = c->n_in;
    const bool final = !repeated(k, n);
    int64_t j = n * kc;
    for (int32_t m = 0; m < kc; m++, j++) {
        const double *u = c->u + (size_t)m * nb * n_in;
        if (c->scheduled) { /* no doStep: its clocks' partitions activated at point j + 1 */
            int32_t code = se_step(k, ci, u, m, j);
            if (code != MK_DONE) return code;
            continue;
        }
        double t = point_time(c, j);
        int terminate = 0, st;
        int64_t t0 = now_ns();
        int32_t call = 0;
        /* FMI 3 event mode: a discrete input that changed is an input event, at t where its sample is of
         * t or earlier, at t + h (after the step, which takes it as it was) where it is of a time in the
         * step, at a later point where it is of a later time */
        const bool held = c->cs_events && c->n_cs_held; /* discrete inputs taken in event mode */
        const bool later = held && discrete_changed(c, u, m, CS_IN_STEP);
        const double *now = held ? held_from(c, u, m, CS_IN_STEP) : u;
        if (held && discrete_changed(c, u, m, CS_AT_START)) {
            if ((st = cs_event(k, ci, now, j, &terminate)) != MK_DONE) return st;
        } else if (n_in && (st = set_inputs(c, now, &call)) > STATUS_OK)
            return fail(k, MK_FMI_ERROR, ci, call, st, j);
        const int32_t n_text_in = c->n_in_string + c->n_in_binary;
        if (n_text_in && (st = set_texts(c, c->in_string_vrs, c->string_u + (size_t)m * n_text_in * MK_STRING_SLOT,
                                         c->n_in_string, c->n_in_binary, &call)) > STATUS_OK)
            return fail(k, MK_FMI_ERROR, ci, call, st, j);
        if (c->n_derivatives && (st = set_derivatives(c, u)) > STATUS_OK)
            return fail(k, MK_FMI_ERROR, ci, MK_CALL_SET_DERIVATIVES, st, j);
        if (terminate) { /* it ended the simulation at the input event: before this step */
            request_stop(k, ci, j - 1, n);
            return MK_STOPPED;
        }
        if (c->me) {
            if ((st = me_step(k, ci, u, t, j, final, &terminate)) != MK_DONE) return st;
        } else if (c->cs_events) {
            if ((st = cs_step(k, ci, u, t, j, final, &terminate)) != MK_DONE) return st;
            if (later && !terminate && /* the input event at t + h */
                (st = cs_event(k, ci, held_from(c, u, m, CS_AFTER_STEP), j, &terminate)) != MK_DONE)
                return st;
        } else if ((st = c->intermediate ? intermediate_step(c, u, t, final, &terminate, &call)
                                         : do_step(c, t, final, &terminate)) > STATUS_OK)
            return fail(k, MK_FMI_ERROR, ci, c->intermediate ? call : MK_CALL_DO_STEP, st, j);
        if (terminate == 2) { /* the step was discarded: the run ends at this macro step's start */
            request_stop(k, ci, j - 1, n);
            return MK_STOPPED;
        }
        /* the step-end inputs, in step mode: the discrete ones of an FMU in event mode as they were set */
        if (c->feedthrough) {
            const double *step_end = held ? held_from(c, u + n_in, m, CS_AT_START) : u + n_in;
            if ((st = set_inputs(c, step_end, &call)) > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, call, st, j);
        }
        double *row = c->hist + ((j + 1) % c->cap) * c->n_out;
        if (c->n_out && c->reads[m] && (st = read_outputs(k, ci, row, j, j + 1)) != MK_DONE) return st;
        if (c->n_out_string + c->n_out_binary && c->reads[m] && (st = read_strings(k, ci, c->strings, j, j + 1)) != MK_DONE)
            return st;
        *c->fmu_time += 1e-9 * (double)(now_ns() - t0);
        (*c->steps)++;
        if (c->n_out && c->reads[m] && check_sample(k, ci, row, j + 1)) return k->error.code;
        if (terminate) { /* completed, and the end: at a macro step's end with it, else at its start
                          * (also in start-up, whose sweeps would step the FMU again) */
            bool with_it = m == kc - 1 && !repeated(k, n);
            request_stop(k, ci, j, with_it ? n + 1 : n);
            return with_it ? MK_DONE : MK_STOPPED;
        }
    }
    return MK_DONE;
}

/* Component ci's linked inputs set to its sources' samples at the end of macro step n (n = -1: the
 * start time): the final samples of every numeric and text link. */
static int32_t set_linked(mk_kernel *k, int32_t ci, int64_t n) {
    mk_component *c = &k->components[ci];
    const int64_t j = (n + 1) * c->step_ratio, t0 = now_ns();
    int st = STATUS_OK;
    int32_t call = MK_CALL_SET_REAL;
    for (int32_t l = 0; st <= STATUS_OK && l < c->n_links; l++) {
        const mk_link *lk = &c->links[l];
        const mk_component *src = &k->components[lk->source];
        const double *row = src->hist + (((n + 1) * lk->k_source) % src->cap) * src->n_out;
        for (int32_t i = 0; i < lk->n_cols; i++) c->scratch[i] = row[lk->columns[i]];
        if (lk->transform) transform_values(lk, c->scratch);
        const int32_t typed = c->n_in - c->n_in_typed; /* a link's inputs are of one kind */
        const int32_t kind = lk->slot0 < c->n_in_real                    ? MK_REAL_SAMPLE
                             : lk->slot0 >= typed                        ? c->in_kinds[lk->slot0 - typed]
                             : lk->slot0 < c->n_in_real + c->n_in_integer ? MK_INTEGER
                                                                         : MK_BOOLEAN;
        st = set_kind(c, kind, lk->vrs, lk->n_vrs, c->scratch, lk->n_cols, &call);
    }
    for (int32_t l = 0; st <= STATUS_OK && l < c->n_string_links; l++) { /* held like Integers: set again */
        const mk_link *lk = &c->string_links[l];
        const mk_component *src = &k->components[lk->source];
        char *to = c->string_u; /* step 0's values as scratch: the next macro step fills them anew */
        for (int32_t i = 0; i < lk->n_cols; i++)
            copy_text(to + (size_t)i * MK_STRING_SLOT,
                      string_slot(src, src->strings, (n + 1) * lk->k_source, lk->columns[i]));
        const bool strings = lk->slot0 < c->n_in_string; /* a link carries one kind */
        st = set_texts(c, c->in_string_vrs + lk->slot0, to, strings ? lk->n_cols : 0, strings ? 0 : lk->n_cols, &call);
    }
    *c->fmu_time += 1e-9 * (double)(now_ns() - t0);
    return st > STATUS_OK ? fail(k, MK_FMI_ERROR, ci, call, st, j > 0 ? j - 1 : 0) : MK_DONE;
}

/* Component ci's outputs that depend on inputs read again into its sample at the end of macro step n
 * (n = -1: the start time): its history row and its text outputs. */
static int32_t read_linked(mk_kernel *k, int32_t ci, int64_t n) {
    mk_component *c = &k->components[ci];
    const int64_t j = (n + 1) * c->step_ratio, t0 = now_ns();
    double *row = c->hist + (j % c->cap) * c->n_out;
    int32_t code = MK_DONE;
    if (c->resample_outputs) code = read_outputs(k, ci, row, j > 0 ? j - 1 : 0, j);
    if (code == MK_DONE && c->resample_texts) code = read_strings(k, ci, c->strings, j > 0 ? j - 1 : 0, j);
    *c->fmu_time += 1e-9 * (double)(now_ns() - t0);
    if (code != MK_DONE) return code;
    return c->resample_outputs ? check_sample(k, ci, row, j) : MK_DONE;
}

/* Before component ci resamples after macro step n: the final samples of its sources, except those
 * of `loop` (solved together with it). */
static int32_t wait_final(mk_kernel *k, int32_t ci, int64_t n, const mk_loop *loop) {
    mk_component *c = &k->components[ci];
    mk_shared *sh = k->shared;
    for (int32_t l = 0; sh && l < c->n_links + c->n_string_links; l++) {
        const mk_link *lk = l < c->n_links ? &c->links[l] : &c->string_links[l - c->n_links];
        bool member = false;
        for (int32_t m = 0; loop && m < loop->n_members; m++) member |= loop->members[m] == lk->source;
        if (member) continue;
        if (wait_for(k, lk->final ? &sh->published[lk->source] : &sh->stepped[lk->source], n + 1)) return aborted(k);
    }
    return MK_DONE;
}

/* An iterated sweep: the sources that go first have completed this sweep (fill_inputs reads them). */
static int32_t wait_swept(mk_kernel *k, const mk_component *c) {
    for (int32_t l = 0; l < c->n_links + c->n_string_links; l++) {
        const mk_link *lk = l < c->n_links ? &c->links[l] : &c->string_links[l - c->n_links];
        if (lk->ahead && wait_for(k, &k->shared->swept[lk->source], k->sweeps)) return aborted(k);
    }
    return MK_DONE;
}

/* Resample component ci after macro step n (kernel.h): its linked inputs set to the sources' final
 * samples at the macro step's end, its outputs read again into its own sample there. */
static int32_t resample(mk_kernel *k, int32_t ci, int64_t n) {
    int32_t code = wait_final(k, ci, n, NULL);
    if (code) return code;
    mark_busy(k, ci);
    code = set_linked(k, ci, n);
    if (code == MK_DONE) code = read_linked(k, ci, n);
    mark_idle(k);
    return code;
}

/* -- algebraic loops (kernel.h: mk_loop) ---------------------------------------------------------- */

/* Unknown i of loop L in its member's sample at the end of macro step n. */
static double *unknown_at(const mk_kernel *k, const mk_loop *L, int32_t i, int64_t n) {
    const mk_component *c = &k->components[L->members[L->unknown_member[i]]];
    return c->hist + (((n + 1) * c->step_ratio) % c->cap) * c->n_out + L->unknown_column[i];
}

/* fx = F(x): x into the histories, every member's linked inputs set from them, then every member's
 * outputs read (Newton's F); or, for the fixed point, member by member in turn, each reading the
 * samples its predecessors just read (Gauss-Seidel: F then depends on the unknowns that drive
 * earlier members alone, a ring on one). */
static int32_t loop_evaluate(mk_kernel *k, mk_loop *L, int64_t n, const double *x, double *fx) {
    int32_t code = MK_DONE;
    const bool in_turn = L->method == MK_LOOP_FIXED_POINT;
    for (int32_t i = 0; i < L->n_unknowns; i++) *unknown_at(k, L, i, n) = x[i];
    for (int32_t m = 0; code == MK_DONE && m < L->n_members; m++) {
        code = set_linked(k, L->members[m], n);
        if (in_turn && code == MK_DONE) code = read_linked(k, L->members[m], n);
    }
    for (int32_t m = 0; !in_turn && code == MK_DONE && m < L->n_members; m++) code = read_linked(k, L->members[m], n);
    for (int32_t i = 0; i < L->n_unknowns; i++) fx[i] = *unknown_at(k, L, i, n);
    L->stats[MK_LOOP_EVALUATIONS]++;
    return code;
}

/* A loop the probe found without cycle: each member once in `order` (its sources final before it),
 * then again those driven by members after them (whose outputs do not depend on those inputs: only
 * the inputs, and the inputs a history holds, change). */
static int32_t loop_sequence(mk_kernel *k, mk_loop *L, int64_t n) {
    int32_t code = MK_DONE;
    for (int32_t p = 0; code == MK_DONE && p < L->n_members; p++) {
        code = set_linked(k, L->members[L->order[p]], n);
        if (code == MK_DONE) code = read_linked(k, L->members[L->order[p]], n);
    }
    for (int32_t p = 0; code == MK_DONE && p < L->n_members; p++)
        if (L->reset[L->order[p]]) { /* read again too: a recorded input may lie in its history */
            code = set_linked(k, L->members[L->order[p]], n);
            if (code == MK_DONE) code = read_linked(k, L->members[L->order[p]], n);
        }
    L->stats[MK_LOOP_EVALUATIONS]++;
    L->stats[MK_LOOP_ITERATIONS]++;
    if (L->stats[MK_LOOP_MOST] < 1) L->stats[MK_LOOP_MOST] = 1;
    return code;
}

static int get_directional_derivative(const mk_component *c, const uint32_t *unknowns, size_t n_unknowns,
                                      const uint32_t *known, const double *seed, double *out) {
    if (c->fmi == 3)
        return ((fmi3_get_directional_derivative *)c->get_directional_derivative)(c->instance, unknowns, n_unknowns,
                                                                                  known, 1, seed, 1, out, n_unknowns);
    return ((fmi2_get_directional_derivative *)c->get_directional_derivative)(c->instance, unknowns, n_unknowns,
                                                                              known, 1, seed, out);
}

/* jac = dF/dx at x (fx = F(x), the members' inputs set to x): from directional derivatives (each
 * member input's seed times its connection's factor), else, or once a call fails, by forward
 * differences (one evaluation per unknown). */
static int32_t loop_jacobian(mk_kernel *k, mk_loop *L, int64_t n, const double *x, const double *fx, double *jac) {
    const int32_t N = L->n_unknowns;
    double *xp = L->work + 5 * N, *fp = L->work + 6 * N;
    L->stats[MK_LOOP_JACOBIANS]++;
    memset(jac, 0, sizeof(double) * (size_t)N * (size_t)N);
    for (int32_t p = 0; L->derivatives && p < L->n_inputs; p++) {
        const int32_t ci = L->members[L->input_member[p]];
        const mk_component *c = &k->components[ci];
        uint32_t vrs[N];
        int32_t rows[N], count = 0;
        for (int32_t i = 0; i < N; i++)
            if (L->unknown_member[i] == L->input_member[p]) {
                vrs[count] = L->unknown_vr[i];
                rows[count++] = i;
            }
        const double seed = 1.0;
        const int64_t t0 = now_ns();
        int st = get_directional_derivative(c, vrs, (size_t)count, &L->input_vr[p], &seed, fp);
        *k->components[ci].fmu_time += 1e-9 * (double)(now_ns() - t0);
        if (st > STATUS_OK) { /* not this FMU's after all: finite differences from now on */
            L->derivatives = 0;
            memset(jac, 0, sizeof(double) * (size_t)N * (size_t)N);
            break;
        }
        for (int32_t q = 0; q < count; q++) jac[rows[q] * N + L->input_unknown[p]] += L->input_factor[p] * fp[q];
    }
    if (L->derivatives) return MK_DONE;
    for (int32_t col = 0; col < N; col++) {
        memcpy(xp, x, sizeof(double) * (size_t)N);
        xp[col] += sqrt(DBL_EPSILON) * fmax(1.0, fabs(x[col]));
        const double d = xp[col] - x[col]; /* the increment as represented */
        int32_t code = loop_evaluate(k, L, n, xp, fp);
        if (code) return code;
        for (int32_t i = 0; i < N; i++) jac[i * N + col] = (fp[i] - fx[i]) / d;
    }
    return MK_DONE;
}

/* The first solve's test of what the FMUs only assumed: entries of `jac` exactly zero where the
 * dependency was assumed are dropped; if no cycle among the members is left, the loop becomes a
 * sequence (kernel.h: mk_loop). */
static void loop_probe(mk_loop *L, const double *jac) {
    const int32_t N = L->n_unknowns, M = L->n_members;
    for (int32_t e = 0; e < N * N; e++)
        L->edges[e] = L->structure[e] == MK_EDGE_ASSUMED && jac[e] == 0.0 ? MK_EDGE_NONE : L->structure[e];
    int32_t indegree[M], position[M];
    bool drives[M * M]; /* drives[a * M + b]: an output of member a reaches an output of member b */
    memset(drives, 0, sizeof drives);
    for (int32_t i = 0; i < N; i++)
        for (int32_t j = 0; j < N; j++)
            if (L->edges[i * N + j] != MK_EDGE_NONE) drives[L->unknown_member[j] * M + L->unknown_member[i]] = true;
    for (int32_t b = 0; b < M; b++) {
        indegree[b] = 0;
        for (int32_t a = 0; a < M; a++) indegree[b] += drives[a * M + b];
    }
    int32_t placed = 0;
    for (bool progress = true; progress;) { /* Kahn, the lowest member first */
        progress = false;
        for (int32_t b = 0; b < M; b++) {
            if (indegree[b] != 0) continue;
            indegree[b] = -1;
            position[b] = placed;
            L->order[placed++] = b;
            for (int32_t c = 0; c < M; c++) indegree[c] -= drives[b * M + c];
            progress = true;
            break;
        }
    }
    L->sequential = placed == M;
    for (int32_t m = 0; L->sequential && m < M; m++) L->reset[m] = 0;
    for (int32_t p = 0; L->sequential && p < L->n_inputs; p++) {
        const int32_t to = L->input_member[p], from = L->unknown_member[L->input_unknown[p]];
        if (position[from] >= position[to]) L->reset[to] = 1;
    }
    L->stats[MK_LOOP_SEQUENTIAL] = L->sequential;
}

/* Anderson's acceleration of the fixed-point step x + r (type II, the last `memory` steps): dx =
 * r - (dX + dR) g where g minimises |r - dR g|, dX and dR the differences of the iterates and of
 * their residuals; on a linear loop of N unknowns it reaches the solution within N + 1 steps. */
static void anderson(mk_loop *L, int32_t it, const double *x, const double *r, double *dx) {
    const int32_t N = L->n_unknowns, M = L->memory;
    double *x_old = L->work + 5 * N, *r_old = L->work + 4 * N;
    double *dX = L->work + 7 * N + 2 * (size_t)N * N, *dR = dX + (size_t)M * N, *a = dR + (size_t)M * N;
    if (it == 0) L->n_history = 0;
    else { /* the newest differences last; the oldest dropped when the memory is full */
        if (L->n_history == M) {
            memmove(dX, dX + N, sizeof(double) * (size_t)(M - 1) * N);
            memmove(dR, dR + N, sizeof(double) * (size_t)(M - 1) * N);
            L->n_history--;
        }
        for (int32_t i = 0; i < N; i++) {
            dX[L->n_history * N + i] = x[i] - x_old[i];
            dR[L->n_history * N + i] = r[i] - r_old[i];
        }
        L->n_history++;
    }
    memcpy(x_old, x, sizeof(double) * (size_t)N);
    memcpy(r_old, r, sizeof(double) * (size_t)N);
    memcpy(dx, r, sizeof(double) * (size_t)N);
    const int32_t m = L->n_history;
    if (m == 0) return;
    double g[m];
    for (int32_t p = 0; p < m; p++) { /* normal equations dR' dR g = dR' r */
        g[p] = 0.0;
        for (int32_t i = 0; i < N; i++) g[p] += dR[p * N + i] * r[i];
        for (int32_t q = 0; q < m; q++) {
            double s = 0.0;
            for (int32_t i = 0; i < N; i++) s += dR[p * N + i] * dR[q * N + i];
            a[p * m + q] = s;
        }
    }
    if (lu_factor(m, a, L->pivot) != 0) { /* dependent differences: start the memory again */
        L->n_history = 0;
        return;
    }
    lu_solve(m, a, L->pivot, g);
    for (int32_t p = 0; p < m; p++)
        for (int32_t i = 0; i < N; i++) dx[i] -= g[p] * (dX[p * N + i] + dR[p * N + i]);
}

/* Solve loop l at the end of macro step n (n = -1: the start time); MK_NOT_CONVERGED if it is not
 * within max_iterations (mk_error: the loop, the largest relative residual, the iterations). */
static int32_t solve_loop(mk_kernel *k, int32_t l, int64_t n) {
    mk_loop *L = &k->loops[l];
    const int32_t N = L->n_unknowns;
    double *x = L->work, *fx = x + N, *r = x + 2 * N, *dx = x + 3 * N;
    double *jac = x + 7 * N, *lu = jac + (size_t)N * N;
    L->stats[MK_LOOP_SOLVES]++;
    if (L->sequential) return loop_sequence(k, L, n);
    for (int32_t i = 0; i < N; i++) x[i] = *unknown_at(k, L, i, n);
    double residual = INFINITY, previous = INFINITY;
    bool have_jacobian = false;
    int32_t it = 0, code;
    for (;; it++) {
        if ((code = loop_evaluate(k, L, n, x, fx))) return code;
        bool converged = true;
        residual = 0.0;
        for (int32_t i = 0; i < N; i++) {
            r[i] = fx[i] - x[i];
            double e = fabs(r[i]) / (1.0 + fabs(fx[i]));
            if (!(e <= L->tolerance)) converged = false;
            residual = isnan(e) || e > residual ? e : residual;
        }
        if (!L->probed) {
            L->probed = 1;
            bool assumed = false;
            for (int32_t e = 0; e < N * N; e++) assumed |= L->structure[e] == MK_EDGE_ASSUMED;
            if (assumed) {
                if ((code = loop_jacobian(k, L, n, x, fx, jac))) return code;
                loop_probe(L, jac);
                if (L->sequential) {
                    L->stats[MK_LOOP_ITERATIONS]++;
                    return loop_sequence(k, L, n);
                }
                have_jacobian = true;
                /* finite differences moved the members' inputs: where x is the answer, back to it
                 * (else the next iterate sets them) */
                if (converged && !L->derivatives && (code = loop_evaluate(k, L, n, x, fx))) return code;
            }
        }
        if (converged) break;
        if (it + 1 >= L->max_iterations) {
            const mk_component *c = &k->components[L->members[0]];
            L->stats[MK_LOOP_ITERATIONS] += it + 1;
            fail(k, MK_NOT_CONVERGED, L->members[0], -1, 0, (n + 1) * c->step_ratio);
            k->error.variable = l;
            k->error.value = residual;
            k->error.integer = (uint64_t)(it + 1);
            return MK_NOT_CONVERGED;
        }
        memcpy(dx, r, sizeof(double) * (size_t)N);
        if (L->method == MK_LOOP_NEWTON) {
            /* the Jacobian kept from earlier points while the residual falls fast (a hundredth
             * per step at least: slower is a stale Jacobian, a few iterations of Newton's rate) */
            if (have_jacobian || !L->fresh || (it > 0 && !(residual <= 0.01 * previous))) {
                if (!have_jacobian && (code = loop_jacobian(k, L, n, x, fx, jac))) return code;
                have_jacobian = false;
                for (int32_t i = 0; i < N; i++)
                    for (int32_t j = 0; j < N; j++) lu[i * N + j] = (i == j) - jac[i * N + j];
                L->fresh = lu_factor(N, lu, L->pivot) == 0;
            }
            if (L->fresh) lu_solve(N, lu, L->pivot, dx); /* singular: a plain fixed-point step */
        } else
            anderson(L, it, x, r, dx);
        for (int32_t i = 0; i < N; i++) x[i] += dx[i];
        previous = residual;
    }
    L->stats[MK_LOOP_ITERATIONS] += it + 1;
    if (L->stats[MK_LOOP_MOST] < it + 1) L->stats[MK_LOOP_MOST] = it + 1;
    if (residual > *L->worst) *L->worst = residual;
    return MK_DONE;
}

/* Resample loop l after macro step n: its members' sources outside it final, then solved. */
static int32_t resample_loop(mk_kernel *k, int32_t l, int64_t n) {
    const mk_loop *L = &k->loops[l];
    for (int32_t m = 0; m < L->n_members; m++)
        if (wait_final(k, L->members[m], n, L)) return MK_ABORTED;
    mark_busy(k, L->members[0]);
    int32_t code = solve_loop(k, l, n);
    mark_idle(k);
    return code;
}

/* Resample entry r of the resampling order after macro step n, where this process steps it: a
 * component or a loop (kernel.h); `due`: a row is recorded after it. */
static int32_t resample_entry(mk_kernel *k, int32_t r, int64_t n, bool due) {
    const int32_t i = k->resample_order[r];
    if (i < 0) return k->components[k->loops[-1 - i].members[0]].local ? resample_loop(k, -1 - i, n) : MK_DONE;
    if (!k->components[i].local || !(due || k->components[i].resample_always)) return MK_DONE;
    return resample(k, i, n);
}

/* Publish the samples of entry r of the resampling order after macro step n (its members'). */
static void publish_entry(mk_kernel *k, int32_t r, int64_t n) {
    const int32_t i = k->resample_order[r];
    if (i >= 0) {
        if (k->components[i].local) publish(&k->shared->published[i], n + 1);
        return;
    }
    const mk_loop *L = &k->loops[-1 - i];
    for (int32_t m = 0; m < L->n_members; m++)
        if (k->components[L->members[m]].local) publish(&k->shared->published[L->members[m]], n + 1);
}

/* Component ci through macro step n: its inputs, then its communication steps, outputs into its
 * history. Relaxed start-up sweeps read the previous sweep's histories, which a barrier has
 * completed. */
static int32_t macro_step(mk_kernel *k, int32_t ci, int64_t n, bool relaxed) {
    mk_component *c = &k->components[ci];
    mk_shared *sh = relaxed ? NULL : k->shared;
    if (sh && wait_inputs(k, c, n)) return MK_ABORTED;
    if (relaxed && k->iterate && k->shared && wait_swept(k, c)) return MK_ABORTED;
    fill_inputs(k, c, n, relaxed);
    if (sh) {
        publish(&sh->consumed[ci], n + 1);
        if (wait_ring(k, c, n)) return MK_ABORTED;
    }
    mark_busy(k, ci);
    int32_t code = communication_steps(k, ci, n);
    mark_idle(k);
    if (code == MK_DONE && sh) {
        publish(&sh->stepped[ci], n + 1);
        if (!(c->resample && !repeated(k, n))) publish(&sh->published[ci], n + 1);
    }
    if (code == MK_DONE && relaxed && k->iterate && k->shared) publish(&k->shared->swept[ci], k->sweeps);
    return code;
}

/* Iterated macro steps: whether this process's components' coupled samples of macro step n changed
 * by at most tolerance (1 + |sample|) in the last sweep (kernel.h: mk_kernel.iterate). If not, *at
 * says where the change relative to 1 + |sample| was largest (component, output, change). */
static bool settled(mk_kernel *k, int64_t n, mk_error *at) {
    bool ok = true;
    double worst = -1.0;
    const uint8_t *coupled = k->coupled;
    for (int32_t ci = 0; ci < k->n_components; coupled += k->components[ci].n_out, ci++) {
        const mk_component *c = &k->components[ci];
        if (!c->local) continue;
        const int32_t nt = c->n_out_string + c->n_out_binary;
        for (int64_t j = n * c->step_ratio + 1; j <= (n + 1) * c->step_ratio; j++) {
            const double *now = c->hist + (j % c->cap) * c->n_out;
            const double *before = c->hist_previous + (j % c->cap) * c->n_out;
            for (int32_t o = 0; o < c->n_out; o++) {
                if (!coupled[o]) continue;
                const double d = fabs(now[o] - before[o]), scale = 1.0 + fabs(now[o]);
                if (d <= k->tolerance * scale) continue;
                ok = false;
                if (d / scale > worst) {
                    worst = d / scale;
                    *at = (mk_error){.code = MK_NOT_SETTLED, .component = ci, .call = -1,
                                     .point = n * c->step_ratio, .variable = o, .value = d};
                }
            }
            for (int32_t i = 0; i < nt; i++) { /* a String or Binary: settled when its bytes stay */
                const char *a = string_slot(c, c->strings, j, i), *b = string_slot(c, c->strings_previous, j, i);
                if (memcmp(a, b, 8 + (size_t)text_length(a)) == 0) continue;
                ok = false;
                if (worst < 0) {
                    worst = 0.0; /* beyond the history's columns: a text output */
                    *at = (mk_error){.code = MK_NOT_SETTLED, .component = ci, .call = -1,
                                     .point = n * c->step_ratio, .variable = c->n_out + i};
                }
            }
        }
    }
    return ok;
}

/* Every process's verdict on the last sweep (`settled`): one that has not settled advances the
 * shared counter before the barrier; after it, all read the same count (none advances it again
 * before the next sweep's barriers). MK_ABORTED if the run is cancelled. */
static int32_t agree(mk_kernel *k, bool *all_settled) {
    if (!k->shared) return MK_DONE;
    if (!*all_settled) advance(k->shared->unsettled, 1);
    if (barrier(k)) return MK_ABORTED;
    const int64_t v = load(k->shared->unsettled);
    *all_settled = v == k->unsettled_seen;
    k->unsettled_seen = v;
    return MK_DONE;
}

/* Start-up macro step n: step it, then repeat it `startup_sweeps` times from the saved FMU states
 * with relaxed windows on the previous sweep's samples (the whole system integrated together).
 * With several processes, barriers separate the sweeps and the snapshots of the histories.
 * Iterated macro steps (k->iterate) take this path at every macro step, sweeping until settled. */
static int32_t startup_step(mk_kernel *k, int64_t n) {
    int32_t code = MK_DONE, saved = 0;
    for (; saved < k->n_components; saved++) {
        mk_component *c = &k->components[saved];
        if (!c->local) continue;
        mark_busy(k, saved);
        int st = ((fmi_get_state *)c->get_state)(c->instance, &c->saved_state);
        me_history(c, true);
        mark_idle(k);
        if (st > STATUS_OK) {
            code = fail(k, MK_FMI_ERROR, saved, MK_CALL_GET_STATE, st, n * c->step_ratio);
            break;
        }
    }
    for (int32_t i = 0; code == MK_DONE && i < k->n_components; i++)
        if (k->components[i].local) code = macro_step(k, i, n, false);
    const int32_t sweeps = k->iterate ? k->iterate : k->startup_sweeps;
    bool done = !k->iterate, mine = true; /* every process's samples settled, this one's */
    mk_error unsettled_at = {0};
    int32_t s = 0;
    for (; code == MK_DONE && s < sweeps && !(k->iterate && done); s++) {
        if ((code = barrier(k))) break;
        for (int32_t i = 0; i < k->n_components; i++) {
            mk_component *c = &k->components[i];
            if (!c->local) continue;
            memcpy(c->hist_previous, c->hist, sizeof(double) * (size_t)c->cap * (size_t)c->n_out);
            if (c->n_out_string + c->n_out_binary)
                memcpy(c->strings_previous, c->strings,
                       (size_t)c->cap * (size_t)(c->n_out_string + c->n_out_binary) * MK_STRING_SLOT);
        }
        if ((code = barrier(k))) break;
        k->sweeps++;
        for (int32_t i = 0; code == MK_DONE && i < k->n_components; i++) {
            mk_component *c = &k->components[i];
            if (!c->local) continue;
            mark_busy(k, i);
            int st = ((fmi_set_state *)c->set_state)(c->instance, c->saved_state);
            me_history(c, false);
            mark_idle(k);
            if (st > STATUS_OK) code = fail(k, MK_FMI_ERROR, i, MK_CALL_SET_STATE, st, n * c->step_ratio);
            else code = macro_step(k, i, n, true);
        }
        if (code == MK_DONE && k->iterate) {
            done = mine = settled(k, n, &unsettled_at);
            if ((code = agree(k, &done))) break;
        }
    }
    if (code == MK_DONE && k->iterate) {
        if (k->iterations && (!k->shared || k->shared->worker == 0)) {
            k->iterations[0] += s;
            if (s > k->iterations[1]) k->iterations[1] = s;
            k->iterations[2]++;
        }
        if (!done && !mine) { /* every process knows; those whose components did not settle say so */
            k->error = unsettled_at;
            k->error.integer = (uint64_t)s;
            code = MK_NOT_SETTLED;
        } else if (!done)
            code = barrier(k); /* settled here: the others fail, the supervisor stops this one */
    }
    if (code == MK_DONE) code = barrier(k); /* the next macro step reads the final sweep's samples */
    /* resampled in order, a barrier after each: its sources' samples are already published */
    const bool due = row_due(k, n);
    for (int32_t r = 0; code == MK_DONE && r < k->n_resample_order; r++) {
        code = resample_entry(k, r, n, due);
        if (code == MK_DONE) code = barrier(k);
    }
    for (int32_t i = 0; i < saved; i++) {
        mk_component *c = &k->components[i];
        if (!c->local) continue;
        mark_busy(k, i);
        int st = ((fmi_free_state *)c->free_state)(c->instance, &c->saved_state);
        mark_idle(k);
        c->saved_state = NULL;
        if (st > STATUS_OK && code == MK_DONE) code = fail(k, MK_FMI_ERROR, i, MK_CALL_FREE_STATE, st, n * c->step_ratio);
    }
    return code;
}

int32_t mk_initial_sweep(mk_kernel *k, int32_t ci) {
    mk_component *c = &k->components[ci];
    double *u = c->u; /* step 0's value block as scratch: macro step 0 fills it anew */
    for (int32_t l = 0; l < c->n_links; l++) {
        const mk_link *lk = &c->links[l];
        const mk_component *src = &k->components[lk->source];
        for (int32_t i = 0; i < lk->n_cols; i++) u[lk->slot0 + i] = src->hist[lk->columns[i]];
        if (lk->transform) transform_values(lk, u + lk->slot0);
    }
    for (int32_t s = 0; s < c->n_stimuli; s++)
        u[c->stimuli[s].slot] = stimulus_value(&c->stimuli[s], point_time(c, 0));
    int st;
    int64_t t0 = now_ns();
    int32_t call = 0;
    int terminate = 0;
    if (c->cs_stepping && c->n_in && discrete_changed(c, u, 0, CS_AT_START)) { /* an input event at the start */
        if ((st = cs_event(k, ci, u, 0, &terminate)) != MK_DONE) return st;
    } else if (c->n_in && (st = set_inputs(c, u, &call)) > STATUS_OK)
        return fail(k, MK_FMI_ERROR, ci, call, st, 0);
    if (c->cs_events) hold_discrete(c, u);
    for (int32_t l = 0; l < c->n_string_links; l++) {
        const mk_link *lk = &c->string_links[l];
        const mk_component *src = &k->components[lk->source];
        char *to = c->string_u + (size_t)lk->slot0 * MK_STRING_SLOT; /* step 0's values as scratch */
        for (int32_t i = 0; i < lk->n_cols; i++)
            copy_text(to + (size_t)i * MK_STRING_SLOT, string_slot(src, src->strings, 0, lk->columns[i]));
    }
    if (c->n_in_string + c->n_in_binary &&
        (st = set_texts(c, c->in_string_vrs, c->string_u, c->n_in_string, c->n_in_binary, &call)) > STATUS_OK)
        return fail(k, MK_FMI_ERROR, ci, call, st, 0);
    if (c->n_out && (st = read_outputs(k, ci, c->hist, 0, 0)) != MK_DONE) return st;
    if (c->n_out_string + c->n_out_binary && (st = read_strings(k, ci, c->strings, 0, 0)) != MK_DONE) return st;
    *c->fmu_time += 1e-9 * (double)(now_ns() - t0);
    /* the sweep of a loop's last member: the loop solved at the start time */
    for (int32_t l = 0; l < k->n_loops; l++)
        if (k->loops[l].members[k->loops[l].n_members - 1] == ci && (st = solve_loop(k, l, -1)) != MK_DONE) return st;
    return MK_DONE;
}

/* Whether the results ring has room for one more row (several processes: wait for the supervisor). */
static int32_t ring_room(mk_kernel *k) {
    if (!k->shared) return k->rows_total - k->rows_drained < k->row_capacity ? MK_DONE : MK_ROWS_FULL;
    return wait_for(k, k->shared->rows_drained, k->rows_total - k->row_capacity + 1) ? aborted(k) : MK_DONE;
}

/* The latest coupling error of link column `index` of component c (mk_record). */
static double coupling_error(const mk_component *c, uint32_t index) {
    for (int32_t l = 0; l < c->n_links; l++) {
        const mk_link *lk = &c->links[l];
        if (index < (uint32_t)lk->n_cols) return lk->error ? lk->error[MK_ERROR_FIELDS * index + 5] : 0.0;
        index -= (uint32_t)lk->n_cols;
    }
    return 0.0;
}

int32_t mk_record_row(mk_kernel *k, int64_t n) {
    int32_t code = ring_room(k);
    if (code) return code;
    const size_t slot = (size_t)(k->rows_total % k->row_capacity);
    double *row = k->rows + slot * (size_t)k->n_columns;
    if (!k->shared || k->shared->worker == 0)
        row[0] = (double)(k->macro_num0 + (n + 1) * k->macro_dnum) / (double)k->macro_den;
    for (int32_t r = 0; r < k->n_records; r++) {
        const mk_record *rec = &k->records[r];
        mk_component *c = &k->components[rec->component];
        if (rec->kind == MK_REAL_SAMPLE) {
            store(row + rec->column, rec->store, c->hist[(((n + 1) * c->step_ratio) % c->cap) * c->n_out + rec->index]);
            continue;
        }
        if (rec->kind == MK_COUPLING_ERROR) {
            row[rec->column] = coupling_error(c, rec->index);
            continue;
        }
        int64_t t0 = now_ns();
        uint64_t length = 0;
        int32_t call = 0;
        int st;
        mark_busy(k, rec->component);
        if (rec->kind == MK_RECORD_STRING || rec->kind == MK_RECORD_BINARY) {
            row[rec->column] = 0.0; /* Python's to fill: the value's place in the results */
            char *to = k->texts + (slot * (size_t)k->n_texts + (size_t)rec->text) * MK_STRING_SLOT;
            call = rec->kind == MK_RECORD_STRING ? MK_CALL_GET_STRING : MK_CALL_GET_BINARY;
            st = get_texts(c, rec->kind, &rec->index, 1, to, &length);
        } else
            st = get_scalar(c, rec->kind, rec->store, rec->index, &row[rec->column], &call);
        mark_idle(k);
        *c->fmu_time += 1e-9 * (double)(now_ns() - t0);
        if (st > STATUS_OK || st < 0) {
            fail(k, st < 0 ? MK_TOO_LONG : MK_FMI_ERROR, rec->component, call, st < 0 ? 0 : st, (n + 1) * c->step_ratio);
            k->error.variable = r;
            k->error.integer = length;
            return k->error.code;
        }
    }
    k->rows_total++;
    if (k->shared) publish(&k->shared->rows_written[k->shared->worker], k->rows_total);
    return MK_DONE;
}

/* -- real-time pacing -------------------------------------------------------------------------- */

#define SPIN_NS 50000 /* sleep until this long before a frame is due, then spin: wake-up jitter */

/* After macro step n: wait until macro step n + 1 is due (absolute clock), or count an overrun. */
static void pace(mk_kernel *k, int64_t n) {
    mk_pacing *p = k->pacing;
    int64_t due = p->origin_ns + (int64_t)llround((double)(n + 1 - p->n_origin) * p->frame * 1e9);
    int64_t now = now_ns(), late;
    if (now > due) {
        p->overruns++;
        late = now - due;
    } else {
        if (due - now > SPIN_NS) {
            int64_t wake = due - SPIN_NS;
            struct timespec ts = {(time_t)(wake / 1000000000), (long)(wake % 1000000000)};
            while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) != 0) {
            }
        }
        int64_t t;
        while ((t = now_ns()) < due) {
        }
        p->idle_ns += t - now;
        late = t - due;
    }
    p->frames++;
    if (late > p->worst_ns) p->worst_ns = late;
    int64_t bin = late / 1000;
    p->histogram[bin < MK_LATE_BINS ? bin : MK_LATE_BINS]++;
}

/* -- the macro-step loop ----------------------------------------------------------------------- */

int32_t mk_run(mk_kernel *k, int64_t n_from, int64_t n_to, double budget_s, int64_t *n_next) {
    const int64_t t_end = budget_s > 0 ? now_ns() + (int64_t)(budget_s * 1e9) : INT64_MAX;
    int32_t code = MK_DONE;
    int64_t n = n_from;
    for (; n < n_to; n++) {
        k->n_now = n;
        if (n >= stop_at(k)) {
            code = MK_STOPPED;
            break;
        }
        const bool due = row_due(k, n); /* also when an FMU ends the run */
        if (due && !k->shared && (code = ring_room(k))) break;
        if (k->shared && load(k->shared->cancel)) {
            code = aborted(k);
            break;
        }
        if (repeated(k, n)) code = startup_step(k, n);
        else {
            for (int32_t i = 0; code == MK_DONE && i < k->n_components; i++)
                if (k->components[i].local) code = macro_step(k, i, n, false);
            for (int32_t r = 0; code == MK_DONE && r < k->n_resample_order; r++) {
                code = resample_entry(k, r, n, due);
                if (code == MK_DONE && k->shared) publish_entry(k, r, n);
            }
        }
        if (code == MK_DONE && due) code = mk_record_row(k, n);
        if (code != MK_DONE) break;
        if (k->pacing->factor > 0) pace(k, n);
        if (now_ns() >= t_end && n + 1 < n_to) {
            n++;
            code = MK_YIELD;
            break;
        }
    }
    *n_next = n;
    return code;
}
