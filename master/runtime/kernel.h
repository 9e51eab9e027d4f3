/* The stepping kernel: the macro-step loop of a compiled plan, with no Python on the per-step path.
 *
 * Python compiles a Plan once into the flat tables below (master/runtime/tables.py fills them,
 * master/runtime/native.py mirrors them with ctypes; mk_layout() lets it check that both agree
 * in size). mk_run() then steps many macro steps per call and returns only when the results
 * buffer is full, a wall-time budget is spent, the requested macro step is reached, or on an
 * error (mk_error says which component, when, why).
 *
 * The arithmetic is the documented one of master/coupling.py (Lagrange weights computed exactly
 * in Python, terms summed in order w0 y0 + w1 y1 + ...), so results are bit for bit those of the
 * Python formulation. Build with -ffp-contract=off: a fused multiply-add would change them.
 * Times are in seconds.
 */
#ifndef MASTER_KERNEL_H
#define MASTER_KERNEL_H

#include <stdbool.h>
#include <stdint.h>

/* Value kinds of coupled signals and recorded values: Real (FMI 2 Real, FMI 3 Float64), Integer
 * (FMI 2 Integer and Enumeration, FMI 3 Int32), Boolean, and the other FMI 3 numeric types, set and
 * read through the calls of their own type (mk_component: set_typed, get_typed; an FMI 3
 * Enumeration is an Int64). Values travel as doubles: exact for Float32 and for integers up to 2^53
 * in magnitude. Real and Float32 signals are extrapolated, the others held (order 0). Strings and
 * FMI 3 Binaries travel as bytes in text rings of their own, held too (MK_STRING_SLOT). */
enum {
    MK_REAL_SAMPLE = 0, MK_INTEGER = 1, MK_BOOLEAN = 2, MK_FLOAT32, MK_INT8, MK_UINT8, MK_INT16, MK_UINT16,
    MK_UINT32, MK_INT64, MK_UINT64, MK_CLOCK_COUNT, MK_KINDS
};
/* MK_CLOCK_COUNT: an FMI 3 Clock connection (output clock -> triggered input clock), never set or read
 * through value calls: the output clock's column holds the ticks counted so far (an exact integer),
 * and a linked input clock ticks where the count it is given has grown (mk_scheduled). */

/* Recorded columns of other kinds (mk_record): a link's latest coupling error, a String and a Binary
 * (read at the row into the results' text ring). */
enum { MK_COUPLING_ERROR = MK_KINDS, MK_RECORD_STRING, MK_RECORD_BINARY };

/* How a recorded value lies in its row's 8 bytes (mk_record.store): a double, or the bits of an
 * int64 / uint64 (an FMI 3 Int64 or UInt64, exact whatever its magnitude). */
enum { MK_STORE_DOUBLE = 0, MK_STORE_INT64 = 1, MK_STORE_UINT64 = 2 };

/* What mk_run returned. */
enum {
    MK_DONE = 0,       /* reached n_to */
    MK_ROWS_FULL = 1,  /* the results buffer is full: drain it, then call again */
    MK_YIELD = 2,      /* the wall-time budget is spent (Python checks for signals, shows progress) */
    MK_FMI_ERROR = 3,  /* an FMI call returned fmi2Error / fmi2Fatal (or worse) */
    MK_NOT_FINITE = 4, /* an output read is NaN or Inf */
    MK_DIVERGED = 5,   /* an output grew beyond its bound */
    MK_ABORTED = 6,    /* another process failed or the supervisor cancelled the run */
    MK_STOPPED = 7,    /* an FMU ended the simulation (FMI 2 fmi2Terminated, FMI 3 terminateSimulation) */
    MK_INEXACT = 8,    /* a 64-bit integer output in a history (a coupled one) is beyond 2^53 in
                          magnitude: a double cannot carry it exactly */
    MK_TOO_LONG = 9,   /* a coupled or recorded String or Binary is longer than MK_TEXT_MAX bytes */
    MK_NOT_CONVERGED = 10, /* an algebraic loop was not solved within its iterations (mk_error: the loop,
                              the residual, the iterations) */
    MK_EVENT = 11,         /* a Model Exchange FMU's event iteration does not end (MK_EVENT_ROUNDS rounds) */
    MK_NOT_SETTLED = 12,  /* iterated macro steps: a coupled signal still changed beyond the tolerance
                             after the most sweeps allowed (mk_error: the component, its output with
                             the largest change and that change, the sweeps in `integer`) */
    MK_CLOCK = 13,        /* a Scheduled Execution FMU counted a clock down by an interval that is not
                             a whole number of its communication steps (mk_error: the clock's index in
                             `variable`, the interval in `value`) */
};

/* String and Binary connections: a coupled String or Binary output is read after each step whose
 * samples are used into the component's text ring, a slot of MK_STRING_SLOT bytes per sample and
 * output, same ring index as its numeric samples; consumers hold it (order 0). A slot holds the
 * value's length in bytes (a uint64), then its bytes, then a zero (a String is a C string there):
 * at most MK_TEXT_MAX bytes. Recorded Strings and Binaries use slots of the same form. */
#define MK_TEXT_MAX 1023
#define MK_STRING_SLOT (8 + MK_TEXT_MAX + 1)

/* Which FMI call failed (mk_error.call). */
enum {
    MK_CALL_SET_REAL, MK_CALL_SET_DERIVATIVES, MK_CALL_DO_STEP, MK_CALL_GET_REAL,
    MK_CALL_GET_STATE, MK_CALL_SET_STATE, MK_CALL_FREE_STATE, MK_CALL_GET_INTEGER, MK_CALL_GET_BOOLEAN,
    MK_CALL_SET_INTEGER, MK_CALL_SET_BOOLEAN, MK_CALL_GET_TYPED, MK_CALL_SET_TYPED, MK_CALL_GET_STRING,
    MK_CALL_SET_STRING, MK_CALL_GET_BINARY, MK_CALL_SET_BINARY,
    /* Model Exchange (mk_component.me): the calls of an integration step, and its solver (status: the
     * solver's code, 2: a singular linear system) */
    MK_CALL_SET_TIME, MK_CALL_SET_STATES, MK_CALL_GET_STATES, MK_CALL_GET_DERIVATIVES, MK_CALL_COMPLETED_STEP,
    MK_CALL_DIRECTIONAL_DERIVATIVE, MK_CALL_SOLVER,
    /* Model Exchange events */
    MK_CALL_GET_EVENT_INDICATORS, MK_CALL_ENTER_EVENT_MODE, MK_CALL_UPDATE_DISCRETE_STATES,
    MK_CALL_ENTER_CONTINUOUS_TIME_MODE,
    /* Scheduled Execution (mk_scheduled) */
    MK_CALL_ACTIVATE_MODEL_PARTITION, MK_CALL_GET_CLOCK, MK_CALL_GET_INTERVAL,
    /* FMI 3 Co-Simulation event mode */
    MK_CALL_ENTER_STEP_MODE, MK_CALL_SET_CLOCK,
};

/* A counter in memory shared between processes, on its own cache line. Waiters spin briefly, then
 * sleep in a futex on its low 32 bits; whoever advances it wakes them. */
typedef struct {
    int64_t value;
    int32_t waiters;
    int32_t pad[13];
} mk_counter;

/* One FMI call of a component with FMI 3 arrays among its inputs or outputs: value references
 * vrs[0..n_vrs) whose values, n_values of them (an array all its elements, row major; a scalar one),
 * lie in a row from index `first` of the inputs or of the history row. Kind: MK_REAL_SAMPLE for
 * Float64, MK_INTEGER (Int32), MK_BOOLEAN or a typed kind. */
typedef struct {
    int32_t kind;
    int32_t first;
    int32_t n_values;
    int32_t n_vrs;
    const uint32_t *vrs;
} mk_call;

/* A connection's transformation of the value it carries (SSP ssc:LinearTransformation with any unit
 * conversion folded in, ssc:BooleanMappingTransformation, ssc:IntegerMappingTransformation,
 * ssc:EnumerationMappingTransformation), applied to the coupled value once the source's signal is
 * extrapolated: MK_TRANSFORM_LINEAR gives factor * value + offset (a derivative block: factor *
 * derivative), MK_TRANSFORM_MAP the `to` value of the first `from` value equal to it (held signals;
 * a value not among them passes unchanged), MK_TRANSFORM_NONE passes it on. The kinds are those of
 * master.scenario.model.TRANSFORMATIONS, in that order (mk_constants lets Python check them). */
enum { MK_TRANSFORM_NONE = 0, MK_TRANSFORM_LINEAR = 1, MK_TRANSFORM_MAP = 2 };

typedef struct {
    int32_t kind;
    int32_t n_map;
    double factor, offset;
    const double *from, *to; /* [n_map] */
} mk_transform;

#define MK_ERROR_FIELDS 6 /* mk_link.error per column: max, sum of squares, count, min, max, latest */

/* One link into a consumer: `n_cols` outputs of `source` drive inputs slot0.. of the consumer.
 *
 * Tables hold, per macro step kind, the sample offsets and weights of every consumer step m:
 * table n (n < n_plain) for plain macro step n, table n_plain for every later plain one, then
 * table n_plain + 1 + n (n < n_relaxed) for the relaxed start-up sweep of macro step n and
 * n_plain + 1 + n_relaxed for later relaxed ones. Sample j of the source is row j % cap of its
 * history; step m of macro step n uses samples n k_source + offsets[t][i][m], i < terms.
 */
typedef struct {
    int32_t source;
    int32_t k_source;
    int32_t ahead; /* 1: the source completes a macro step before the consumer starts it */
    int32_t final; /* 1: the source reads these outputs again (resampling): wait for its published
                      sample, 0: its stepped one */
    int32_t n_cols;
    int32_t slot0;
    const int32_t *columns; /* source history column of each driven input */
    int32_t n_vrs;          /* value references of the driven inputs (fewer than n_cols where FMI 3 */
    const uint32_t *vrs;    /* arrays are among them: an array's elements share one) */
    int32_t terms;          /* polynomial order + 1 */
    int32_t n_plain;
    int32_t n_relaxed;
    const int64_t *offsets; /* [table][term][m] */
    const double *weights;  /* [table][block][term][m] */
    const uint8_t *zero;    /* [table][block][m]: exactly 0.0 whatever the samples */
    const double *scale;    /* [block]: source step ** derivative order (1 for value blocks) */
    /* The coupling error estimate of an extrapolated link: in macro step n its polynomial through
     * samples n k_source - i (weights `predict`, i < terms) predicts sample (n + 1) k_source;
     * in macro step n + 1 that sample is known. error[c]: max |prediction - sample|, sum of
     * squares, count, the smallest and largest sample seen (the signal's range), and the latest
     * |prediction - sample| (0 until the first; a recorded column, MK_COUPLING_ERROR). */
    const double *predict; /* [terms], NULL: no estimate (a source that goes first) */
    double *predicted;     /* [n_cols] */
    double *error;         /* [n_cols][MK_ERROR_FIELDS] */
    /* [n_cols]: each column's transformation; NULL where none has one (the hot path checks this
     * once per link, never per value) */
    const mk_transform *transform;
} mk_link;

/* A step or table signal on an input slot of its component (see master/coupling.py). */
typedef struct {
    int32_t slot;
    int32_t kind; /* 0: step (values[i] from times[i] on), 1: table (piecewise linear) */
    int32_t n;
    const double *times;
    const double *values;
    double start_value; /* a step stimulus before times[0] */
} mk_stimulus;

/* An FMI function of any signature (cast to its own type before the call). */
typedef void (*mk_function)(void);

/* FMI 3 intermediate update: the instanceEnvironment of an FMU that providesIntermediateUpdate and
 * whose inputs are polynomials (interpolateInputs), passed with mk_intermediate_update at its
 * instantiation (Python owns it). Where the FMU asks inside doStep (intermediateVariableSetRequested),
 * the callback sets its n scalar Float64 inputs declared intermediateUpdate="true" (value references
 * vrs, the component's Real input slots `slots`) to the step's input polynomials at the time asked, in
 * the arithmetic of an FMI 2 FMU handed them as input derivatives (fmus/fmi/step.c), with one
 * fmi3SetFloat64 into `values`; no allocation. The kernel points it at its component, the step's
 * input blocks and communication point before each doStep, and clears u after it: outside the
 * kernel's doStep the callback sets nothing (inputs held). status: the worst status of those calls
 * (the callback returns none: the kernel checks it after the step); calls counts them. */
typedef struct {
    const void *component; /* the mk_component */
    const double *u;
    double t0;
    int32_t n;
    const int32_t *slots;
    const uint32_t *vrs;
    double *values;
    int32_t status;
    int64_t calls;
} mk_intermediate;

/* A Scheduled Execution component (master/clocks.py): no doStep; in each communication step, from
 * point j to j + 1 of its grid, its inputs (those at t_{j+1}) are set, the partitions of its input
 * clocks that tick at point j + 1 activated with fmi3ActivateModelPartition(clock, t_{j+1}), its
 * outputs read into sample j + 1 (sample-and-hold at activations); point 0 at the start time, after
 * initialisation (mk_scheduled_start). Input clocks in activation order (priority), each activated at
 * most once per point, the highest-priority one due first after every activation: a periodic one
 * (MK_TICK_PERIODIC) at points phase + i every, a triggered one at its listed points, a countdown one
 * (MK_TICK_COUNTDOWN) at the point the FMU's fmi3GetIntervalDecimal announced after an activation
 * (due: -1 none), a linked one (MK_TICK_LINKED, a triggered clock connected to an output clock) at
 * the points where its input slot, the source's tick count, differs from the count it last saw
 * (seen). Output clocks are read with fmi3GetClock after each point's activations and their
 * ticks counted (mk_component.out_clock_ticks). */
enum { MK_TICK_PERIODIC = 0, MK_TICK_COUNTDOWN = 1, MK_TICK_TRIGGERED = 2, MK_TICK_LINKED = 3 };
#define MK_MAX_CLOCKS 64 /* input clocks of one component */

typedef struct {
    int32_t n_clocks;
    const uint32_t *vrs;   /* [n_clocks] */
    const int32_t *tick;   /* [n_clocks]: MK_TICK_* */
    const int64_t *every;  /* [n_clocks] */
    const int64_t *phase;  /* [n_clocks] */
    const int64_t *first;  /* [n_clocks + 1]: a triggered clock's points: points[first[i] .. first[i + 1]) */
    const int64_t *points; /* ascending */
    int64_t *due;          /* [n_clocks] */
    int64_t *activations;  /* [n_clocks]: counted */
    const int32_t *slot;   /* [n_clocks]: a linked clock's input slot (-1: not linked) */
    double *seen;          /* [n_clocks]: a linked clock's count when it last ticked */
    mk_function activate_model_partition, get_interval; /* fmi3ActivateModelPartition, fmi3GetIntervalDecimal */
} mk_scheduled;

/* One FMU instance and its place in the plan. Pointers stay owned by Python. */
typedef struct {
    /* FMI: version 1 (Co-Simulation: the FMI 2 calls, with one-byte Booleans and no FMU state), 2 or
     * 3, the instance and the functions the loop calls */
    int32_t fmi;
    void *instance;
    mk_function do_step, set_real, get_real, set_derivatives, get_integer, get_boolean, set_integer, set_boolean;
    mk_function get_state, set_state, free_state, get_boolean_status;
    mk_function get_directional_derivative; /* algebraic loops solved with directional derivatives */
    mk_function get_typed[MK_KINDS]; /* FMI 3: fmi3Get<type> of kinds MK_FLOAT32 ... MK_UINT64 */
    mk_function set_typed[MK_KINDS]; /* FMI 3: fmi3Set<type> of the same kinds */
    /* clock: communication point j is (num0 + j dnum) / den; step_ratio steps of h per macro step (the scenario's stepRatio k) */
    int64_t num0, dnum, den;
    double h;
    int32_t step_ratio;
    /* inputs: u[m][block][i], blocks = n_values values (step start, step end) then derivatives;
     * the first n_in_real are Real (FMI 3 Float64), the next n_in_integer Integer (Int32, FMI 2
     * Enumeration), then Boolean ones, and the last n_in_typed of the FMI 3 kinds in_kinds[i]
     * (MK_FLOAT32 ... MK_UINT64, those of one kind together, set one kind per call): discrete ones
     * travel as exact doubles, held (order 0). An FMI 3 array takes a slot per element (in_vrs: its
     * value reference in each); where arrays are among the inputs, n_in_calls > 0 and the inputs are
     * set by the calls in_calls (one per kind, each passing its arrays' value references once with
     * all their elements) instead */
    int32_t n_in;
    int32_t n_in_real, n_in_integer, n_in_typed;
    const int32_t *in_kinds; /* [n_in_typed] */
    const uint32_t *in_vrs;
    int32_t n_in_calls;
    const mk_call *in_calls;
    int32_t n_blocks;
    int32_t n_values;
    int32_t feedthrough; /* set the step-end inputs after doStep (outputs depend on inputs) */
    int32_t n_derivatives;            /* n_in_real * (n_blocks - n_values): Real inputs only */
    const uint32_t *derivative_vrs;   /* [n_derivatives]: [derivative block][Real input] */
    const int32_t *derivative_orders; /* [n_derivatives] */
    double *u;
    int32_t n_links;
    const mk_link *links;
    int32_t n_stimuli;
    const mk_stimulus *stimuli;
    /* outputs: history ring [cap][n_out]; read after step m only where reads[m]; Real first, then
     * n_out_integer Integer, then Boolean, then n_out_typed of kinds out_kinds (as for the inputs;
     * an FMI 3 array a column per element, read by the calls out_calls where n_out_calls > 0) */
    int32_t n_out;
    int32_t n_out_real, n_out_integer, n_out_typed;
    const int32_t *out_kinds; /* [n_out_typed] */
    const uint32_t *out_vrs;
    int32_t n_out_calls;
    const mk_call *out_calls;
    double *hist;
    double *hist_previous; /* start-up: the previous sweep's samples, [cap][n_out] */
    int32_t cap;
    const uint8_t *reads;
    const double *bound; /* |output| beyond this has diverged */
    /* Resampling: no output lags its time label. After each macro step (a start-up one after its
     * last sweep) a component that reads an output of any type depending on its inputs (coupled or
     * recorded) sets its linked inputs (held and text ones too) again to the sources' final samples
     * at the macro step's end, then reads its history row again (resample_outputs: a history column
     * depends on inputs) and its text outputs (resample_texts), before the sample is published;
     * recorded outputs outside the history are read after it (tables.resampling says which). */
    int32_t resample;
    int32_t resample_always; /* 0: the re-read outputs are recorded, never coupled: only at the
                                macro steps that record a row */
    int32_t resample_outputs, resample_texts;
    double *scratch;              /* [n_in] */
    int32_t n_consumers; /* components reading this history (they hold its ring back) */
    const int32_t *consumers;
    int32_t local;       /* stepped by this process */
    /* String and Binary connections (none: every count 0, nothing is called). Outputs: n_out_string
     * coupled String outputs then n_out_binary Binary ones (out_string_vrs: theirs), read with
     * get_string (fmi2GetString / fmi3GetString) and get_binary (fmi3GetBinary) wherever reads[m],
     * into strings[sample % cap][i][MK_STRING_SLOT] (hist_previous's twin: strings_previous).
     * Inputs: n_in_string String then n_in_binary Binary ones (in_string_vrs), set with set_string
     * and set_binary before each step from string_u[m][i][MK_STRING_SLOT], which fill_inputs copies
     * from the sources' rings: string_links are mk_links of one term (held) whose columns index the
     * source's text outputs and slot0 the text inputs, a link of one kind (the numeric fields
     * weights, zero, scale, predict: unused). */
    mk_function get_string, set_string, get_binary, set_binary;
    int32_t n_out_string, n_out_binary;
    const uint32_t *out_string_vrs;
    char *strings;          /* [cap][n_out_string + n_out_binary][MK_STRING_SLOT] */
    char *strings_previous; /* start-up: the previous sweep's */
    int32_t n_in_string, n_in_binary;
    const uint32_t *in_string_vrs;
    int32_t n_string_links;
    const mk_link *string_links;
    char *string_u; /* [step_ratio][n_in_string + n_in_binary][MK_STRING_SLOT] */
    /* written by the kernel */
    void *saved_state;
    /* counted as they happen, in shared memory: a worker that dies or hangs leaves its counts */
    int64_t *steps;   /* communication steps */
    double *fmu_time; /* wall time inside FMI calls, s */
    /* Model Exchange (me = 1): the kernel integrates the FMU's n_states continuous states itself, in
     * each communication step from t to t + h by me_substeps steps of the shared solver me_solver
     * (fmus/solvers: SolverKind), its Real inputs at every stage time the polynomial of the step's
     * blocks (value at t, then derivatives: u(s) = u0 + d1 dt + d2 dt^2 / 2 + d3 dt^3 / 6, as a
     * Co-Simulation FMU that interpolates its inputs evaluates it), then fmi2/3CompletedIntegratorStep
     * after each step; its outputs are read as a Co-Simulation FMU's. me_state_vrs and
     * me_derivative_vrs (NULL: none) give the semi-implicit methods their Jacobian from directional
     * derivatives, else finite differences. me_memory is the multistep history (solver_memory_size
     * doubles), saved with the FMU state in start-up (me_memory_saved); me_work a SolverWork. */
    int32_t me;
    int32_t me_solver;
    int32_t me_substeps;
    int32_t n_states;
    mk_function set_time, set_states, get_states, get_derivatives, completed_step;
    const uint32_t *me_state_vrs;
    const uint32_t *me_derivative_vrs;
    double *me_x;            /* [n_states] */
    double *me_memory;
    double *me_memory_saved;
    void *me_work;
    /* Model Exchange events (fmus/solvers/events.c ode_advance): time events met exactly
     * (me_next_event: the FMU's nextEventTime, INFINITY none; saved in start-up with the history),
     * the n_event_indicators indicators watched after each step and a sign change located to
     * me_tolerance s (<= 0: EVENT_TOLERANCE), step events from fmi2/3CompletedIntegratorStep; each
     * event: enter event mode, the event iteration, the states read back, continuous-time mode, the
     * history restarted. me_events: an EventWork; *me_event_count counts the events handled. */
    int32_t n_event_indicators;
    mk_function get_event_indicators, enter_event_mode, update_discrete_states, enter_continuous_time_mode;
    double me_next_event;
    double me_next_event_saved;
    double me_tolerance;
    void *me_events;
    int64_t *me_event_count;
    /* 1: inputs that FMI lets change in event mode only (discrete ones: Integer, Boolean, String, ...):
     * the FMU rests in event mode between communication steps (its inputs and outputs set and read
     * there) and each communication step begins with the event iteration (an input event) and
     * continuous-time mode; the history restarts only where the states changed. */
    int32_t me_input_events;
    /* FMI 3 intermediate update (NULL: none): the instance's environment, answered by
     * mk_intermediate_update */
    mk_intermediate *intermediate;
    mk_scheduled *scheduled; /* NULL: none (a Co-Simulation or Model Exchange component) */
    /* FMI 3 Co-Simulation in event mode (cs_events = 1: instantiated with eventModeUsed and early return
     * allowed, master/fmu.py). doStep returns at an event (eventHandlingNeeded; earlyReturn with
     * lastSuccessfulTime, the event's time, inside the step): the kernel does the event iteration there
     * (fmi3EnterEventMode, fmi3UpdateDiscreteStates until none is needed, fmi3EnterStepMode) and, after
     * an early return, steps on from that time to the step's end, the inputs held: the component's
     * communication points stay the schedule's. A discrete input (any kind but Real and Float32) that
     * changes is set in event mode with an event iteration (an input event) at the time of the sample
     * that brings the change: at the step's start where that sample is of its start or earlier, else
     * (a source that goes first, a relaxed sweep: a sample of a later time; cs_late, written with the
     * inputs) after the step, which takes the value as it was. A discrete signal thus passes from an
     * event of its source to its consumers at their first point where they see the new sample.
     * cs_held: the n_cs_held discrete inputs as last set (saved with the FMU state in start-up:
     * cs_held_saved); events are counted in *me_event_count. */
    int32_t cs_events;
    mk_function enter_step_mode;
    int32_t cs_stepping; /* 1 once out of initialisation mode: the start time's sweeps after it set a
                            changed discrete input through an input event too */
    int32_t n_cs_held;
    uint8_t *cs_late; /* [step_ratio][n_in]: 1 where a held input's sample of step m is of a later time */
    double *cs_held;
    double *cs_held_saved;
    /* FMI 3 output clocks whose ticks are counted (MK_CLOCK_COUNT columns): a Scheduled Execution
     * component's (mk_scheduled's arrays), read after each point's activations; a Co-Simulation
     * component's in event mode, read with fmi3GetClock after each event iteration (cs_event) */
    int32_t n_out_clocks;
    const uint32_t *out_clock_vrs; /* [n_out_clocks] */
    int64_t *out_clock_ticks;      /* [n_out_clocks]: counted */
    mk_function get_clock;         /* fmi3GetClock */
    mk_function set_clock;         /* fmi3SetClock: in an input event, a linked input clock whose source's
                                      count grew since it was last set (MK_CLOCK_COUNT inputs) */
} mk_component;

/* One recorded column: a sample from a history, a value read from the FMU at the row through the
 * call of its kind, the latest coupling error of one of the component's links' columns (the row
 * after macro step n holds the error found at the start of macro step n: of the prediction of the
 * source's sample at the macro step's start, made in macro step n - 1, one macro step before the
 * row's time), or a String or Binary read at the row into slot `text` of the row's text ring (its
 * place in the row is Python's to fill). */
typedef struct {
    int32_t column; /* in the row (0 is time) */
    int32_t component;
    int32_t kind;   /* MK_REAL_SAMPLE: history column `index`; MK_COUPLING_ERROR: link column `index`
                       (the component's links' columns counted in link order); any other kind:
                       value reference */
    uint32_t index;
    int32_t store;  /* MK_STORE_*: how the value lies in the row */
    int32_t text;   /* MK_RECORD_STRING, MK_RECORD_BINARY: the text ring's column */
} mk_record;

typedef struct {
    int32_t code;
    int32_t component;
    int32_t call;
    int32_t status;
    int64_t point;    /* communication point j at the start of the failing step */
    int32_t variable; /* output index (MK_NOT_FINITE, MK_DIVERGED, MK_INEXACT; MK_TOO_LONG: of the
                         text outputs, or with call MK_CALL_GET_STRING / _BINARY a record index) or
                         record index */
    int32_t kind;     /* the value kind of a failing MK_CALL_SET_TYPED / MK_CALL_GET_TYPED */
    double value;
    uint64_t integer; /* MK_INEXACT: the integer read (an Int64 as its two's complement bits);
                         MK_TOO_LONG: the String's or Binary's length in bytes */
} mk_error;

/* Per-frame lateness of real-time pacing: a histogram in microseconds and the extremes. */
#define MK_LATE_BINS 10000
typedef struct {
    double factor;    /* simulated seconds per wall second; 0: unpaced */
    double frame;     /* wall seconds per macro step (macro step / factor) */
    int64_t origin_ns; /* CLOCK_MONOTONIC ns at which macro step n_origin is due to start */
    int64_t n_origin;
    int64_t frames;
    int64_t overruns;
    int64_t worst_ns;
    int64_t idle_ns;
    int64_t histogram[MK_LATE_BINS + 1]; /* [us], last bin: MK_LATE_BINS us and more */
} mk_pacing;

/* What several processes share: progress counters per component, the start-up barrier, the
 * results ring's counters, a cancel flag and what each process is doing (for hang detection). */
typedef struct {
    mk_counter *published;    /* [n_components]: macro steps completed, samples final */
    mk_counter *stepped;      /* [n_components]: macro steps stepped (a resampling component's
                                 samples of outputs that do not depend on inputs are final) */
    mk_counter *consumed;     /* [n_components]: macro steps whose inputs are taken */
    mk_counter *barrier;      /* arrivals at start-up barriers */
    mk_counter *rows_written; /* [n_workers]: rows whose columns each worker has written */
    mk_counter *rows_drained; /* rows the supervisor has taken out of the ring */
    mk_counter *cancel;       /* non-zero: stop at the next wait or macro step */
    mk_counter *stop_at;      /* an FMU ended the simulation: no macro step from this one on */
    int64_t *stopper;         /* [n_components][2]: a component's stop request (first macro step
                                 not to begin) and its communication point */
    int64_t *busy;            /* [2]: CLOCK_MONOTONIC ns at which this worker's FMU step began (0:
                                 none running), and that component */
    mk_counter *unsettled;    /* iterated macro steps: advanced by every process whose components'
                                 coupled samples still changed in a sweep (read after a barrier) */
    mk_counter *swept;        /* [n_components]: iterated sweeps a component has completed (a
                                 consumer of a source that goes first waits for its current sweep) */
    int32_t worker;
    int32_t n_workers;
    int64_t spin_ns; /* how long a waiter spins before it sleeps */
} mk_shared;

/* How an algebraic loop is solved (master.scenario.model.LOOP_METHODS, in that order), what one of
 * its Jacobian entries is known to be (master.schedule.EDGE_*), and its counters (mk_loop.stats). */
enum { MK_LOOP_NEWTON = 0, MK_LOOP_FIXED_POINT = 1 };
enum { MK_EDGE_NONE = 0, MK_EDGE_DECLARED = 1, MK_EDGE_ASSUMED = 2 };
enum {
    MK_LOOP_SOLVES, MK_LOOP_ITERATIONS, MK_LOOP_EVALUATIONS, MK_LOOP_JACOBIANS, MK_LOOP_MOST, MK_LOOP_SEQUENTIAL,
    MK_LOOP_STATS = 8
};

/* An algebraic loop (master.schedule.Loop): components whose outputs depend directly on their inputs
 * around a cycle, all stepped by one process. Where samples are final (a macro step's end, the
 * start time) it is solved for its unknowns x, the members' history columns that drive members'
 * inputs: F(x) sets every member's linked inputs from the histories holding x and reads every
 * member's outputs again (no step), until |F(x)_i - x_i| <= tolerance (1 + |F(x)_i|) for every i;
 * the histories then hold F(x), read with inputs x. Newton on F(x) - x with the Jacobian of F from
 * directional derivatives or finite differences, reused from point to point while the residual
 * falls fast, or Anderson-accelerated fixed-point steps. Entries the FMU only assumed (no dependencies
 * declared) that the first solve finds exactly zero are dropped; where that leaves no cycle among
 * the members, every later solve evaluates them once each in `order` (exact, no iteration). */
typedef struct {
    int32_t n_members;
    const int32_t *members; /* component indices */
    int32_t n_unknowns;
    const int32_t *unknown_member; /* [n]: index into members */
    const int32_t *unknown_column; /* [n]: that member's history column */
    const uint32_t *unknown_vr;    /* [n]: its value reference */
    const uint8_t *structure;      /* [n][n]: MK_EDGE_* of d unknown i / d unknown j */
    int32_t n_inputs;              /* the members' inputs that unknowns drive */
    const int32_t *input_member;   /* [n_inputs]: index into members */
    const uint32_t *input_vr;
    const int32_t *input_unknown;
    const double *input_factor; /* the connection's linear factor (1: none) */
    int32_t method;
    int32_t derivatives; /* 1: the Jacobian from directional derivatives (0 after one fails) */
    double tolerance;
    int32_t max_iterations;
    /* written by the kernel: the probe's result, and work space */
    int32_t probed, sequential, fresh;
    int32_t *order;   /* [n_members] */
    uint8_t *edges;   /* [n][n]: the structure after the probe */
    uint8_t *reset;   /* [n_members]: set its inputs again after a sequential pass */
    int32_t memory;   /* Anderson's: at most this many earlier steps (m) */
    int32_t n_history;
    double *work;     /* [7 n + 2 n n + 2 m n + m m]: x, fx, r, dx, previous r, previous x (or a perturbed
                         x), F of it; Jacobian, LU; Anderson's differences of x and of r, his matrix */
    int32_t *pivot;   /* [n] */
    int64_t *stats;   /* [MK_LOOP_STATS], in shared memory */
    double *worst;    /* the largest residual accepted (shared memory) */
} mk_loop;

typedef struct {
    int32_t n_components;
    mk_component *components; /* in stepping order */
    int64_t n_macro;
    int64_t startup_steps;
    int32_t startup_sweeps;
    int64_t record_every;
    int64_t macro_num0, macro_dnum, macro_den; /* macro step n starts at (num0 + n dnum) / den */
    int32_t n_columns;
    int32_t n_records;
    const mk_record *records; /* the local components' columns */
    /* results ring [row_capacity][n_columns]: row r in slot r % row_capacity; recorded Strings and
     * Binaries in texts[row_capacity][n_texts][MK_STRING_SLOT], same slot */
    double *rows;
    char *texts;
    int32_t n_texts;
    int64_t row_capacity;
    int64_t rows_total;   /* rows begun by this process */
    int64_t rows_drained; /* one process: rows Python has taken out (several: see shared) */
    mk_shared *shared;    /* NULL: one process steps everything, Python drains the ring itself */
    int64_t barriers;     /* start-up barriers this process has passed */
    int64_t n_now;        /* the macro step being stepped */
    int64_t stop_at;      /* one process: as mk_shared.stop_at */
    int64_t stopper[2];   /* one process: as mk_shared.stopper */
    mk_pacing *pacing;
    mk_error error;
    int32_t n_resample_order;
    const int32_t *resample_order; /* resampling components, sources of input-dependent outputs first;
                                      -1 - l: algebraic loop l, its members resampled together */
    int32_t n_loops;
    mk_loop *loops;
    /* Iterated macro steps (strong coupling): iterate > 0 repeats every macro step from the saved FMU
     * states, as the start-up sweeps do, until no coupled sample of it (n k + 1 .. (n + 1) k of
     * every column `coupled` marks, and every coupled String or Binary) changes by more than
     * tolerance (1 + |sample|) between sweeps, in at most `iterate` sweeps (else MK_NOT_SETTLED).
     * Its relaxed sweeps read a source that goes first from the current sweep (Gauss-Seidel
     * waveform iteration; start-up sweeps without it read every source's previous sweep). Several
     * processes agree through shared->unsettled, so every one does the same sweeps. */
    int32_t iterate;           /* most sweeps per macro step; 0: explicit coupling */
    double tolerance;
    const uint8_t *coupled;    /* [sum of n_out over the components, in stepping order] */
    int64_t *iterations;       /* [3]: sweeps in all, most in one macro step, macro steps iterated
                                  (written by the only process, or worker 0: all count the same) */
    int64_t sweeps;            /* sweeps this process has done (the target of shared->swept) */
    int64_t unsettled_seen;    /* shared->unsettled as last read */
} mk_kernel;

/* Sizes of the structures, for the ctypes mirror to check itself against. */
void mk_layout(int64_t *sizes);
/* Constants the ctypes mirror and the tables share: MK_KINDS, MK_COUPLING_ERROR, MK_ERROR_FIELDS,
 * MK_STRING_SLOT, MK_TEXT_MAX, MK_TRANSFORM_NONE, MK_TRANSFORM_LINEAR, MK_TRANSFORM_MAP, the loops',
 * SOLVER_COUNT (the Model Exchange components' methods, master.solvers.SOLVERS). */
void mk_constants(int64_t *values);
/* Initial sweep of component c (initialisation mode): inputs from the sources' sample 0, own
 * outputs into sample 0. Returns an mk code. */
int32_t mk_initial_sweep(mk_kernel *k, int32_t c);
/* Record the row after macro step n (n = -1: the start time) into the results ring. */
int32_t mk_record_row(mk_kernel *k, int64_t n);
/* A Scheduled Execution component's activations at the start time (point 0), after initialisation,
 * its outputs read into sample 0. Returns an mk code. */
int32_t mk_scheduled_start(mk_kernel *k, int32_t c);
/* Step macro steps n_from .. n_to - 1 (fewer on a return other than MK_DONE); *n_next: the first
 * macro step not done. budget_s > 0: return MK_YIELD once that much wall time has passed. */
int32_t mk_run(mk_kernel *k, int64_t n_from, int64_t n_to, double budget_s, int64_t *n_next);
/* fmi3IntermediateUpdateCallback of FMUs with an mk_intermediate environment (see there). */
void mk_intermediate_update(void *environment, double time, bool set_requested, bool get_allowed,
                            bool step_finished, bool can_return_early, bool *early_return_requested,
                            double *early_return_time);
/* Set a counter and wake its waiters (the supervisor draining the results ring). */
void mk_publish(mk_counter *c, int64_t value);
/* Raise the cancel flag and wake every waiter (a supervisor stopping the run). */
void mk_cancel(mk_shared *s, int32_t n_components, int32_t n_workers);
/* No process begins macro step n_stop or a later one (a component failed in it): the others
 * complete the macro steps before it, and their rows, then stop. Wakes every waiter. */
void mk_stop(mk_shared *s, int64_t n_stop, int32_t n_components, int32_t n_workers);

#endif
