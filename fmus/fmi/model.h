/* model.h: the contract between the shared FMI layer (fmus/fmi: FMI 2.0, and FMI 3.0
 * Co-Simulation) and one model.
 *
 * A model is one C file (fmus/<name>/model.c) that defines `const ModelDef MODEL`:
 * its variable table and its equations.  It never touches FMI state handling.
 *
 * Storage: every variable lives in a slot of one of the arrays of the instance
 * (reals, integers, booleans, strings; for FMI 3.0 types also int64s, uint64s,
 * binaries).  The value reference of a variable is its position in the variable
 * table (FMI 3.0: unique across all types, as the standard requires).  Slot 0 of
 * the reals and of the integers belongs to the shared layer (internal_step, solver);
 * models number their own slots from R_MODEL_START / I_MODEL_START.  An array
 * (FMI 3.0) occupies consecutive slots from its `slot`, row major.  Anything a
 * model must remember between calls (e.g. a Newton warm start) goes into a local
 * real slot, so that FMU state get/set/serialize copies it too.
 */
#ifndef MODEL_H
#define MODEL_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>

/* Variable types.  The first five exist in FMI 2.0 and 3.0; a table that uses any of the
 * others (or an array) builds as FMI 3.0 only and says so with `.fmi3_only = 1`. */
typedef enum {
    T_REAL,    /* FMI 2.0 Real, FMI 3.0 Float64 (alias T_FLOAT64); real slot */
    T_INTEGER, /* FMI 2.0 Integer, FMI 3.0 Int32 (alias T_INT32); integer slot (int) */
    T_BOOLEAN, /* boolean slot (int, 0 or 1) */
    T_STRING,  /* string slot: up to STRING_CAPACITY - 1 bytes */
    T_SOLVER,  /* Enumeration "Solver" (values 1 .. SOLVER_COUNT); integer slot; FMI 3.0: Int64-valued */
    /* FMI 3.0 only */
    T_FLOAT32, /* real slot: a double holds every float exactly; the layer rounds on get */
    T_INT8,    /* T_INT8 .. T_INT64: int64 slot (int64_t); fmi3Set<T> only passes values of the type */
    T_UINT8,
    T_INT16,
    T_UINT16,
    T_UINT32,
    T_INT64,
    T_UINT64,  /* uint64 slot (uint64_t) */
    T_BINARY,  /* binary slot: up to BINARY_CAPACITY bytes; start_string gives the start as hex digits */
    T_CLOCK,   /* Scheduled Execution (ModelDef.clocks): integer slot, an output clock's tick (1: ticked since
                  fmi3GetClock read it) or an input clock's interval qualifier (2: changed, a countdown) */
    T_COUNT
} VarType;
#define T_FLOAT64 T_REAL
#define T_INT32 T_INTEGER

#define STRING_CAPACITY 2048 /* bytes per String slot, terminating zero included */
#define BINARY_CAPACITY 256 /* bytes per Binary slot */
#define MAX_DIMENSIONS 3    /* dimensions of an FMI 3.0 array variable */
typedef enum { C_PARAMETER, C_CALCULATED_PARAMETER, C_INPUT, C_OUTPUT, C_LOCAL, C_INDEPENDENT } Causality;
typedef enum { V_CONSTANT, V_FIXED, V_TUNABLE, V_DISCRETE, V_CONTINUOUS } Variability;
typedef enum { I_DEFAULT, I_EXACT, I_APPROX, I_CALCULATED } Initial; /* I_DEFAULT: attribute omitted */

/* MODEL_ERROR: this evaluation failed (Error); MODEL_FATAL: the model cannot go on (Fatal);
 * MODEL_TERMINATE (from derivatives or outputs): the model ends the simulation after this step
 * (FMI 2.0: fmi2Discard and fmi2Terminated; FMI 3.0: fmi3OK with *terminateSimulation = true). */
typedef enum { MODEL_OK = 0, MODEL_ERROR = 1, MODEL_FATAL = 2, MODEL_TERMINATE = 3 } ModelStatus;

/* Solvers of the shared core (values of the `solver` parameter): master/solvers.py names them,
 * and master/fmubuild.py checks this enumeration against that table before every build. */
typedef enum {
    SOLVER_EULER = 1,
    SOLVER_AB2 = 2,
    SOLVER_AB3 = 3,
    SOLVER_RK4 = 4,
    SOLVER_SEMI_IMPLICIT_EULER = 5,
    SOLVER_SEMI_IMPLICIT_MIDPOINT = 6
} SolverKind;
enum { SOLVER_COUNT = SOLVER_SEMI_IMPLICIT_MIDPOINT }; /* solvers are numbered 1 .. SOLVER_COUNT */

enum { R_INTERNAL_STEP = 0, R_MODEL_START = 1 };
enum { I_SOLVER = 0, I_MODEL_START = 1 };

#define NO_STATE (-1)

typedef struct {
    const char *name;
    VarType type;
    Causality causality;
    Variability variability;
    Initial initial;
    int slot;                 /* index into the array of this type */
    double start;             /* start value of numbers and Booleans (every element of an array); ignored where
                                 initial is calculated.  64-bit integers: exact up to 2^53 */
    const char *start_string; /* start value of a String; of a Binary: hex digits ("0a1b") */
    double min, max;          /* enforced on set (numbers, compared as doubles); -INFINITY / INFINITY for none */
    const char *unit;         /* NULL: none */
    const char *description;
    int derivative_of;        /* Real state derivatives: value reference of the state; NO_STATE otherwise */
    const char *dependencies; /* outputs, derivatives and calculated initial unknowns: space separated value
                                 references of the inputs/states they depend on ("" = none, NULL = all,
                                 "states" = every continuous state) */
} Variable;

typedef struct Instance Instance;

/* FMI 3.0 Scheduled Execution: the attributes of a Clock variable (T_CLOCK). */
typedef enum { CLOCK_CONSTANT, CLOCK_FIXED, CLOCK_TUNABLE, CLOCK_CHANGING, CLOCK_COUNTDOWN, CLOCK_TRIGGERED } ClockVariability;
typedef struct {
    int vr;                       /* the Clock variable */
    ClockVariability variability; /* intervalVariability */
    double interval;              /* constant, fixed, tunable: intervalDecimal [s] */
    int priority;                 /* input clocks: the smaller, the more urgent */
    int interval_slot;            /* countdown: real slot of the interval it counts down; -1 none */
} ClockDef;

/* What an event update (ModelDef.update) reports: the layer presets changed = 0 and next_event_time =
 * INFINITY (no time event). */
typedef struct {
    int changed;            /* 1: it changed discrete variables or states, and is called again (the event
                               iteration: FMI newDiscreteStatesNeeded) until it changes nothing */
    double next_event_time; /* the next time event [s]; INFINITY: none */
} EventUpdate;

typedef struct {
    const char *identifier; /* modelIdentifier: the shared library's name */
    const char *guid;
    const char *description;

    const Variable *variables;
    int n_variables;
    int n_reals, n_integers, n_booleans, n_strings; /* slot counts, including the layer's slot 0s */
    int n_int64s, n_uint64s, n_binaries;            /* FMI 3.0 slot counts (0 when unused) */

    /* FMI 3.0 arrays: per variable the extents of its dimensions, unused ones 0 ({3}: a vector of
     * 3, {2, 2}: a 2x2 matrix, {0}: a scalar).  NULL: every variable is a scalar. */
    const int (*dimensions)[MAX_DIMENSIONS];
    /* 1: the table uses FMI 3.0 types or arrays and builds as FMI 3.0 only (write it literally,
     * `.fmi3_only = 1`: master/fmubuild.py reads it from the source to list FMI 2.0 models). */
    int fmi3_only;
    /* 1: the description offers Model Exchange alone (no CoSimulation element, no FMI 1.0 build), as
     * tools that export Model Exchange only do (write it literally, `.me_only = 1`, as fmi3_only). */
    int me_only;

    /* DefaultExperiment stepSize in seconds (written in the model description); 0: none. */
    double default_step_size;

    int n_states;
    const int *state_slots;      /* real slots of the continuous states, in state order */
    const int *derivative_slots; /* real slots of their derivatives, same order */

    /* Called on ExitInitializationMode, after parameters and start values are set:
     * derive calculated parameters, make the initial state consistent.  May be NULL. */
    ModelStatus (*initialize)(Instance *inst);

    /* dx = f(t, x).  Inputs in the real slots already hold their values at time t
     * (the layer evaluates input polynomials before the call).  Must not write
     * state slots; may write locals (e.g. warm starts).  NULL: a model without states. */
    ModelStatus (*derivatives)(Instance *inst, double t, const double *x, double *dx);

    /* J = df/dx at (t, x), row major n_states x n_states.  NULL: finite differences. */
    ModelStatus (*jacobian)(Instance *inst, double t, const double *x, double *J);

    /* Write outputs and other dependent variables for time t and state x
     * (the layer has already copied x into the state slots).  May be NULL.
     * MODEL_TERMINATE (after writing the outputs): the simulation ends at time t; in a step
     * the layer reports it when the step that reached t completes. */
    ModelStatus (*outputs)(Instance *inst, double t, const double *x);

    /* 1: `outputs` also writes the derivative slots with f(t, x) as `derivatives` computes it. The
     * layer keeps the latest evaluation of f (time, states, Real inputs and the result), so that a
     * step whose first evaluation has the same arguments does not repeat it: the master reads
     * outputs that depend on inputs again at a communication point, then steps from there. */
    int outputs_give_derivatives;
    /* 1: f does not depend on t itself, so a kept evaluation serves whatever the rounding of the
     * communication point's time (else the time must match to the bit). */
    int autonomous;

    /* Events (Model Exchange: the importer handles them; Co-Simulation: doStep does, with the same
     * method as the master, fmus/solvers/events.c).  None of them: a model without events. */
    int n_event_indicators;
    /* FMI 3.0 ModelStructure/EventIndicator: the value reference of a variable per indicator whose value
     * it is (FMI 3.0 requires one); NULL: FMI 2.0 only. */
    const int *event_indicator_vrs;
    /* z[0 .. n_event_indicators) at (t, x): an event when one changes its domain (z > 0 against z <= 0). */
    ModelStatus (*event_indicators)(Instance *inst, double t, const double *x, double *z);
    /* The event at time t (a time event, a state event, a step event; and once after initialization, the
     * initial event iteration): may change the states x and discrete variables, says what it changed
     * and the next time event in *ev.  MODEL_TERMINATE: the simulation ends here.  NULL: none. */
    ModelStatus (*update)(Instance *inst, double t, double *x, EventUpdate *ev);
    /* Step events: after each completed integrator step at (t, x); 1 asks for an event.  NULL: none. */
    int (*step_event)(Instance *inst, double t, const double *x);

    /* FMI 3.0 Scheduled Execution (fmus/fmi/clocks.c): a model with clocks offers that interface alone
     * (`.fmi3_only = 1`) and need not list COMMON_VARIABLES.  clocks: one per T_CLOCK variable;
     * clocked: per variable its `clocks` attribute (value references, "" / NULL none), NULL: none;
     * activate: the model partition of input clock clock_vr at time t, which may tick output clocks
     * (model_tick) and count clocks down (model_count_down). */
    const ClockDef *clocks;
    int n_clocks;
    const char *const *clocked;
    ModelStatus (*activate)(Instance *inst, int clock_vr, double t);
} ModelDef;

extern const ModelDef MODEL;

/* What the layer offers models. */
double *model_reals(Instance *inst);
int *model_integers(Instance *inst);
int *model_booleans(Instance *inst);
int64_t *model_int64s(Instance *inst);
uint64_t *model_uint64s(Instance *inst);
/* The instance's current time: the start time during initialization (MODEL.initialize). */
double model_time(Instance *inst);
const char *model_string(Instance *inst, int slot);
/* Writes a String slot, cut to STRING_CAPACITY - 1 bytes; returns 1 if it was cut. */
int model_set_string(Instance *inst, int slot, const char *value);
/* The bytes of a Binary slot; *size receives their number. */
const unsigned char *model_binary(Instance *inst, int slot, size_t *size);
/* Writes a Binary slot; returns 1 and writes nothing if size > BINARY_CAPACITY. */
int model_set_binary(Instance *inst, int slot, const void *data, size_t size);
/* Scheduled Execution: output clock clock_vr ticks now; countdown clock clock_vr ticks `interval` s
 * from now.  Both tell the importer (its clockUpdate callback). */
void model_tick(Instance *inst, int clock_vr);
void model_count_down(Instance *inst, int clock_vr, double interval);
/* Log through the FMI callback; category one of "logError", "logWarning", "logInfo", "logDebug". */
void model_log(Instance *inst, const char *category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* The two variables every model lists first in its table. */
#define COMMON_VARIABLES(default_solver, default_internal_step)                                           \
    {"solver", T_SOLVER, C_PARAMETER, V_FIXED, I_EXACT, I_SOLVER, (default_solver),                       \
     NULL, 1, SOLVER_COUNT, NULL,                                                                         \
     "fixed-step solver: 1 euler, 2 ab2, 3 ab3, 4 rk4, 5 semi-implicit euler, 6 semi-implicit midpoint",  \
     NO_STATE, NULL},                                                                                     \
    {"internal_step", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_INTERNAL_STEP, (default_internal_step),    \
     NULL, 0, INFINITY, "s",                                                                              \
     "solver step inside a communication step; 0: one step per communication step",                       \
     NO_STATE, NULL}

#endif
