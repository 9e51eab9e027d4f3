/* instance.h: the instance of the shared FMI layer (internal to fmus/fmi).
 *
 * The layer itself knows no FMI version: fmi2.c (FMI 2.0) and fmi3.c (FMI 3.0
 * Co-Simulation) are thin interfaces over it, and an FMU is built with one of them.
 * They share the instance, its state machine and settability rules, get/set checks,
 * FMU state copies and serialization (instance.c), the step (step.c), directional
 * derivatives (derivative.c) and logging (log.c).  Logging reaches the importer
 * through `emit`, which the interface file sets.
 *
 * Everything that must survive GetFMUstate/SetFMUstate lives in ONE contiguous
 * block (`block`): the Core header, the real/integer/boolean/string slots (the
 * continuous states among the reals), the solver memory, the input polynomials and
 * the FMI 3.0 int64/uint64/binary slots.  Offsets are computed from the ModelDef
 * counts at instantiation, so a state copy is a memcpy and serialization writes the
 * block behind a small header.  Scratch buffers (the state vector, solver work,
 * finite differences, what one doStep remembers) live outside the block and are
 * never part of the state.
 */
#ifndef INSTANCE_H
#define INSTANCE_H

#include "model.h"
#include "solvers.h"

#define MAX_INPUT_ORDER 3 /* highest order accepted by fmi2SetRealInputDerivatives */

/* Status of a layer call: the order of fmi2Status and fmi3Status, so the interfaces cast it. */
typedef enum { LAYER_OK, LAYER_WARNING, LAYER_DISCARD, LAYER_ERROR, LAYER_FATAL } LayerStatus;

typedef enum { KIND_CO_SIMULATION, KIND_MODEL_EXCHANGE } InstanceKind;

/* States of an instance (FMI 2.0 CS and ME, FMI 3.0 CS share one enumeration and one rule set). */
typedef enum {
    ST_INSTANTIATED,
    ST_INITIALIZATION,
    ST_STEP_COMPLETE,     /* CS (FMI 3.0: Step Mode) */
    ST_EVENT,             /* ME */
    ST_CONTINUOUS_TIME,   /* ME */
    ST_TERMINATED,
    ST_ERROR,
    ST_COUNT
} FmiState;

#define MASK(s) (1u << (s))
#define ANY_STATE ((1u << ST_COUNT) - 1u)

#define S_INST MASK(ST_INSTANTIATED)
#define S_INIT MASK(ST_INITIALIZATION)
#define S_STEP MASK(ST_STEP_COMPLETE)
#define S_EVENT MASK(ST_EVENT)
#define S_CONT MASK(ST_CONTINUOUS_TIME)
#define S_TERM MASK(ST_TERMINATED)
#define S_ERR MASK(ST_ERROR)

#define S_SET (S_INST | S_INIT | S_STEP | S_EVENT | S_CONT)         /* set values */
#define S_GET (S_INIT | S_STEP | S_EVENT | S_CONT | S_TERM | S_ERR) /* get values */

/* Masks of variable types (1u << VarType) for get/set checks. */
#define TYPE_MASK(t) (1u << (t))

/* Head of the persistent block. */
typedef struct {
    double time;            /* current time [s] */
    int state;              /* FmiState */
    int outputs_dirty;      /* inputs, parameters or states changed since MODEL.outputs ran */
    int derivatives_dirty;  /* ... since the derivative slots were written */
    int have_input_derivatives; /* some fmi2SetRealInputDerivatives since the last doStep */
    int initialized;        /* Initialization Mode: MODEL.initialize ran and only inputs changed since */
    int fatal;              /* the model reported MODEL_FATAL: the step ends with Fatal */
    int terminate;          /* the model reported MODEL_TERMINATE: the simulation ends after this step */
    double next_event_time; /* the model's pending time event (INFINITY: none) */
    long long events;       /* events handled (Co-Simulation: inside doStep) */
    /* FMI 3.0 Co-Simulation in event mode (Instance.event_mode_used): doStep stopped at an event that the
     * importer handles in event mode (event_pending); where it returned early, the step's grid of
     * internal steps, which the doStep completing it goes on with (grid_steps 0: none) */
    int event_pending;
    long long grid_steps;
    double grid_t0, grid_h, grid_t1;
} Core;

/* A Binary slot of the block. */
typedef struct {
    uint64_t size;
    unsigned char data[BINARY_CAPACITY];
} BinarySlot;

/* Hands one message to the importer's logger; the interface file knows its signature. */
typedef void (*EmitFn)(const Instance *inst, LayerStatus status, const char *category, const char *message);

struct Instance {
    const ModelDef *model;
    char *name;
    InstanceKind kind;
    int fmi_version;         /* 1, 2 or 3: the interface that created the instance (names in messages) */
    EmitFn emit;
    void (*logger)(void);    /* the importer's logger, cast back to its own type by emit */
    void *env;               /* the importer's environment pointer, passed to the logger */
    int scheduled;           /* FMI 3.0 Scheduled Execution (clocks.c); its Clock Activation Mode is Step Mode */
    void (*clock_update)(void *env); /* its importer's fmi3ClockUpdateCallback (NULL: none) */
    unsigned log_mask;       /* bit per category, see log.c */
    char model_error[512];   /* the model's last logError message, repeated in the layer's failure report */
    char error_suffix[512];  /* returned by model_error_suffix */

    /* persistent block and views into it */
    unsigned char *block;
    size_t block_size;
    Core *core;
    double *reals;
    double *memory;          /* solver memory, solver_memory_size(n_states) */
    double *input_derivs;    /* n_real_inputs x MAX_INPUT_ORDER polynomial coefficients */
    int *integers;
    int *booleans;
    char *strings;           /* n_strings x STRING_CAPACITY */
    int64_t *int64s;
    uint64_t *uint64s;
    BinarySlot *binaries;

    /* constant tables derived from MODEL */
    int n_real_inputs;       /* elements of the Real (Float64) inputs */
    int *real_input_slot;    /* Real slot of each of them */
    int *input_index;        /* per value reference: index of its first element among them, or -1 */
    int n_checked;
    int *checked_vr;         /* Real/Float32 states and outputs, checked for finiteness after each step */

    /* scratch, not state */
    SolverWork *work;
    double *x;               /* continuous states, n_states: filled by gather_states before each use */
    double *dx;              /* n_states */
    double *input_values;    /* Real inputs as the master set them for the running doStep, n_real_inputs */
    double comm_point;       /* t_c: start of the running doStep [s] (origin of the input polynomials) */
    double comm_end;         /* its end [s] */
    /* FMI 3.0 Co-Simulation, as instantiated (hasEventMode: a model with events): doStep stops at an event
     * and leaves it to event mode, at once where early return is allowed, else at the step's end only */
    int event_mode_used;
    int early_return_allowed;
    double *jac;             /* n_states x n_states */
    double *saved_reals;     /* n_reals: finite differences restore from here */
    double *fd_seed_base;    /* n_variables: known values around which to differentiate */
    double *fd_plus, *fd_minus; /* n_variables */

    EventWork *events;       /* the state events' scratch (fmus/solvers/events.c) */
    double *z;               /* n_event_indicators: fmi2/3GetEventIndicators */

    /* the latest evaluation of f (keep_rhs): not state, forgotten when anything but a Real input or
     * the states and time changes */
    int rhs_kept;
    double rhs_t;
    double *rhs_x, *rhs_dx;  /* n_states */
    double *rhs_u;           /* n_real_inputs */

    /* FMI 3.0 intermediate update (step.c inputs_at): ask_inputs, set by fmi3.c where the importer passed
     * a callback, asks it for the intermediate-update inputs (intermediate_input) of time t inside doStep
     * (NULL: inputs held, or the FMI 2.0 input polynomials); callback: the importer's, cast back by
     * fmi3.c; asked_time: the time last asked in the running doStep (NAN: none yet); in_intermediate_update:
     * inside the callback, where only those inputs may be set. Not state. */
    void (*ask_inputs)(Instance *inst, double t);
    void (*callback)(void);
    double asked_time;
    int in_intermediate_update;
};

/* log.c */
enum { LOG_ERROR = 0, LOG_WARNING = 1, LOG_INFO = 2, LOG_DEBUG = 3, LOG_N_CATEGORIES = 4 };
extern const char *const LOG_CATEGORY_NAMES[LOG_N_CATEGORIES];
extern const char *const LOG_CATEGORY_DESCRIPTIONS[LOG_N_CATEGORIES];
void layer_log(Instance *inst, int category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* ": <model's last error>" (or "") for appending to a failure report; clears it. */
const char *model_error_suffix(Instance *inst);
/* The name of a state as the instance's FMI version calls it. */
const char *state_name(const Instance *inst, int state);
/* 1 if the instance may make this call in its current state, else logs and returns 0. */
int check_state(Instance *inst, const char *function, unsigned allowed_mask);
/* SetDebugLogging: all categories (n == 0) or the named ones on or off. */
LayerStatus set_debug_logging(Instance *inst, const char *function, int on, size_t n,
                              const char *const categories[]);

/* instance.c */
Instance *instance_new(const char *name, InstanceKind kind, int fmi_version, EmitFn emit, void (*logger)(void),
                       void *env, int logging_on);
void instance_free(Instance *inst);
void instance_reset(Instance *inst); /* start values, time 0, state Instantiated */
/* The variable behind vr, or NULL.  FMI 3.0 instances also know `time`, the independent
 * variable, at vr = n_variables. */
const Variable *variable_of(const Instance *inst, unsigned vr);
/* Number of values of the variable: the product of its dimensions, 1 for a scalar. */
size_t variable_size(const Instance *inst, unsigned vr);
const char *type_name(const Instance *inst, int type);
Initial effective_initial(const Variable *v);
/* 1 for an input the importer may set in Intermediate Update Mode (FMI 3.0 intermediateUpdate="true"):
 * a continuous Float64 input (master/fmubuild.py declares the same ones). */
int intermediate_input(const Variable *v);
/* NULL if `v` may be set in the current state, else the reason. */
const char *not_settable_reason(const Instance *inst, const Variable *v);
/* The variable behind vr if it exists and its type is in `types`; else logs and returns NULL. */
const Variable *lookup(Instance *inst, const char *function, unsigned vr, unsigned types);
/* Checks a get (set = 0) or set (set = 1) of the variables vr[0..nvr): each exists and has a
 * type in `types`, their values number n_values, and for a set each may be set in the current
 * state and each value (value_at(values, j) as a double; value_at NULL for non-numbers) is
 * finite and inside [min, max].  Logs the first problem and returns 0; 1 if there is none. */
int check_access(Instance *inst, const char *function, const unsigned vr[], size_t nvr, unsigned types,
                 size_t n_values, int set, double (*value_at)(const void *values, size_t j), const void *values);
/* check_access for a get, then refresh (derivatives too when a derivative is asked for). */
int prepare_get(Instance *inst, const char *function, const unsigned vr[], size_t nvr, unsigned types,
                size_t n_values);
void gather_states(Instance *inst, double *x);       /* state slots -> x */
void scatter_states(Instance *inst, const double *x); /* x -> state slots */
void mark_dirty(Instance *inst);
/* Keep dx = f(t, x) at the current Real inputs (an outputs evaluation of a model whose outputs
 * compute f); kept_rhs: 1 and dx if (t, x, inputs) match it (t ignored for an autonomous model),
 * else 0; forget_rhs: none kept. */
void keep_rhs(Instance *inst, double t, const double *x, const double *dx);
int kept_rhs(Instance *inst, double t, const double *x, double *dx);
void forget_rhs(Instance *inst);
/* After SetXXX of vr[0..nvr): outputs are stale; in Initialization Mode a changed
 * parameter or start value also means MODEL.initialize must run again. */
void note_set(Instance *inst, const unsigned vr[], size_t nvr);
/* MODEL.initialize unless Core.initialized says it already ran; 0 on success (logs on failure). */
int run_initialize(Instance *inst, const char *function);
/* MODEL.outputs at the current time and states; 0 on success (no logging).  MODEL_TERMINATE
 * counts as success and sets Core.terminate. */
int eval_outputs(Instance *inst);
/* MODEL.derivatives at the current time and states, into the derivative slots; 0 on success
 * (no logging). */
int eval_derivatives(Instance *inst);
/* Bring outputs (and derivative slots when `derivatives`) up to date; 0 on success.
 * In Initialization Mode MODEL.initialize runs first unless it already ran for the
 * parameters and start values as they are (so initial outputs are the model's, and a
 * model with side effects in initialize sees one call per set of values).  In the Error
 * state nothing is evaluated: the values stay as the failure left them. */
int refresh(Instance *inst, int derivatives, const char *function);
/* 0 if every state and Real output is finite, else logs the first bad one and returns 1. */
int check_finite(Instance *inst, const char *function);

/* The state machine's transitions, shared by the interfaces. */
/* Start (and optional stop) time of the experiment; 0 and logs if invalid. */
int setup_experiment(Instance *inst, const char *function, double start, int stop_defined, double stop);
void enter_initialization(Instance *inst);
/* Runs MODEL.initialize, moves to StepComplete (CS) or EventMode (ME) and computes the outputs. */
LayerStatus exit_initialization(Instance *inst, const char *function);

/* FMU state: copies of the block (GetFMUstate, SetFMUstate, FreeFMUstate, serialization). */
LayerStatus state_get(Instance *inst, const char *function, void **state);
LayerStatus state_set(Instance *inst, const char *function, const void *state);
void state_free(void **state);
LayerStatus state_serialized_size(Instance *inst, const void *state, size_t *size);
LayerStatus state_serialize(Instance *inst, const char *function, const void *state, unsigned char *buffer,
                            size_t size);
LayerStatus state_deserialize(Instance *inst, const char *function, const unsigned char *buffer, size_t size,
                              void **state);

/* step.c */
LayerStatus do_step(Instance *inst, const char *function, double t, double H);
/* Model rhs/Jacobian with the input polynomials evaluated at time t (solver callbacks). */
int rhs_with_inputs(void *ctx, double t, const double *x, double *dx);
int jac_with_inputs(void *ctx, double t, const double *x, double *J);
/* doStep's events (OdeProblem.indicators, .completed, .event), the inputs of time t as for f. */
int indicators_with_inputs(void *ctx, double t, const double *x, double *z);
int completed_in_step(void *ctx, double t, const double *x, int *event, int *stop);
int event_in_step(void *ctx, double t, double *x, double *next_time, int *stop);

/* event.c: the model's events through the layer. */
/* The event update at the current time and states, once: *needed (it changed something: call again),
 * *states_changed, *terminate; the next time event into Core.  0 on success (logs on failure). */
int event_update(Instance *inst, const char *function, int *needed, int *states_changed, int *terminate);
/* Whether the model has events (indicators, an event update or step events): FMI 3.0 Co-Simulation
 * offers Event Mode for it (hasEventMode). */
int model_has_events(const ModelDef *m);
/* The whole event iteration (event_update until nothing changes), as doStep and initialization run it;
 * one that does not end leaves its reason as the model's error (model_error_suffix) for the caller. */
int event_iteration(Instance *inst, const char *function, int *states_changed, int *terminate);
/* The model's indicators at the current time and states into z; 0 on success. */
int event_indicators_now(Instance *inst, double *z);

/* clocks.c: FMI 3.0 Scheduled Execution (ModelDef.clocks). The partition of input clock vr at time t;
 * output clocks read (ticked: 1, each reset by the read); the intervals of clocks (qualifiers: FMI 3.0's
 * fmi3IntervalQualifier, a countdown's reset to unchanged by the read). */
LayerStatus clock_activate(Instance *inst, const char *function, unsigned vr, double t);
LayerStatus clock_get(Instance *inst, const char *function, const unsigned vr[], size_t nvr, int ticked[]);
/* A Co-Simulation model's input clocks set active (1) or not in Event Mode: the model's update reads
 * their slots (and clears them) in that event iteration. */
LayerStatus clock_set(Instance *inst, const char *function, const unsigned vr[], size_t nvr, const int active[]);
LayerStatus clock_intervals(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                            double intervals[], int qualifiers[]);

/* derivative.c: d(unknowns)/d(knowns) * seed for scalar Real variables. */
LayerStatus directional_derivative(Instance *inst, const char *function, const unsigned unknown[],
                                   size_t n_unknown, const unsigned known[], size_t n_known, const double seed[],
                                   double result[]);

#endif
