/* model.h: the contract between the shared FMI 2.0 layer (fmus/fmi) and one model.
 *
 * A model is one C file (fmus/<name>/model.c) that defines `const ModelDef MODEL`:
 * its variable table and its equations.  It never touches FMI state handling.
 *
 * Storage: every variable lives in a slot of one of four arrays of the instance
 * (reals, integers, booleans, strings).  The value reference of a variable is its
 * position in the variable table.  Slot 0 of the reals and of the integers belongs
 * to the shared layer (internal_step, solver); models number their own slots from
 * R_MODEL_START / I_MODEL_START.  Anything a model must remember between calls
 * (e.g. a Newton warm start) goes into a local real slot, so that FMU state
 * get/set/serialize copies it too.
 */
#ifndef MODEL_H
#define MODEL_H

#include <math.h>
#include <stddef.h>

typedef enum { T_REAL, T_INTEGER, T_BOOLEAN, T_STRING, T_SOLVER } VarType; /* T_SOLVER: Enumeration "Solver" */
typedef enum { C_PARAMETER, C_CALCULATED_PARAMETER, C_INPUT, C_OUTPUT, C_LOCAL, C_INDEPENDENT } Causality;
typedef enum { V_CONSTANT, V_FIXED, V_TUNABLE, V_DISCRETE, V_CONTINUOUS } Variability;
typedef enum { I_DEFAULT, I_EXACT, I_APPROX, I_CALCULATED } Initial; /* I_DEFAULT: attribute omitted */

/* MODEL_ERROR: this evaluation failed (fmi2Error); MODEL_FATAL: the model cannot go on (fmi2Fatal);
 * MODEL_TERMINATE: the model ends the simulation after this step (fmi2Discard, fmi2Terminated). */
typedef enum { MODEL_OK = 0, MODEL_ERROR = 1, MODEL_FATAL = 2, MODEL_TERMINATE = 3 } ModelStatus;

/* Solvers of the shared core (values of the `solver` parameter). */
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
    double start;             /* start value (Real, Integer, Boolean, Solver); ignored where initial is calculated */
    const char *start_string; /* start value of a String */
    double min, max;          /* enforced on set (Real, Integer); use -INFINITY / INFINITY for none */
    const char *unit;         /* NULL: none */
    const char *description;
    int derivative_of;        /* Real state derivatives: value reference of the state; NO_STATE otherwise */
    const char *dependencies; /* outputs, derivatives and calculated initial unknowns: space separated value
                                 references of the inputs/states they depend on ("" = none, NULL = all,
                                 "states" = every continuous state) */
} Variable;

typedef struct Instance Instance;

typedef struct {
    const char *identifier; /* modelIdentifier: the shared library's name */
    const char *guid;
    const char *description;

    const Variable *variables;
    int n_variables;
    int n_reals, n_integers, n_booleans, n_strings; /* slot counts, including the layer's slot 0s */

    int n_states;
    const int *state_slots;      /* real slots of the continuous states, in state order */
    const int *derivative_slots; /* real slots of their derivatives, same order */

    /* Called on fmi2ExitInitializationMode, after parameters and start values are set:
     * derive calculated parameters, make the initial state consistent.  May be NULL. */
    ModelStatus (*initialize)(Instance *inst);

    /* dx = f(t, x).  Inputs in the real slots already hold their values at time t
     * (the layer evaluates input polynomials before the call).  Must not write
     * state slots; may write locals (e.g. warm starts). */
    ModelStatus (*derivatives)(Instance *inst, double t, const double *x, double *dx);

    /* J = df/dx at (t, x), row major n_states x n_states.  NULL: finite differences. */
    ModelStatus (*jacobian)(Instance *inst, double t, const double *x, double *J);

    /* Write outputs and other dependent variables for time t and state x
     * (the layer has already copied x into the state slots).  May be NULL. */
    ModelStatus (*outputs)(Instance *inst, double t, const double *x);
} ModelDef;

extern const ModelDef MODEL;

/* What the layer offers models. */
double *model_reals(Instance *inst);
int *model_integers(Instance *inst);
int *model_booleans(Instance *inst);
const char *model_string(Instance *inst, int slot);
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
