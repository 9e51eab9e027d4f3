/* instance.h: the instance of the shared FMI 2.0 layer (internal to fmus/fmi).
 *
 * Everything that must survive fmi2GetFMUstate/fmi2SetFMUstate lives in ONE
 * contiguous block (`block`): the Core header, the real/integer/boolean/string
 * slots (the continuous states among the reals), the solver memory and the
 * input polynomials.  Offsets are computed from the ModelDef counts at
 * instantiation, so a state copy is a memcpy and serialization writes the
 * block behind a small header.  Scratch buffers (the state vector, solver
 * work, finite differences, what one doStep remembers) live outside the block
 * and are never part of the state.
 */
#ifndef INSTANCE_H
#define INSTANCE_H

#include "fmi2Functions.h"
#include "model.h"
#include "solvers.h"

#define STRING_CAPACITY 256   /* bytes per String slot, terminating zero included */
#define MAX_INPUT_ORDER 3     /* highest order accepted by fmi2SetRealInputDerivatives */

/* FMI 2.0 states of an instance (CS and ME share one enumeration). */
typedef enum {
    ST_INSTANTIATED,
    ST_INITIALIZATION,
    ST_STEP_COMPLETE,     /* CS */
    ST_EVENT,             /* ME */
    ST_CONTINUOUS_TIME,   /* ME */
    ST_TERMINATED,
    ST_ERROR,
    ST_COUNT
} FmiState;

#define MASK(s) (1u << (s))
#define ANY_STATE ((1u << ST_COUNT) - 1u)

/* Head of the persistent block. */
typedef struct {
    double time;            /* current time [s] */
    int state;              /* FmiState */
    int outputs_dirty;      /* inputs, parameters or states changed since MODEL.outputs ran */
    int derivatives_dirty;  /* ... since the derivative slots were written */
    int have_input_derivatives; /* some fmi2SetRealInputDerivatives since the last doStep */
    int initialized;        /* Initialization Mode: MODEL.initialize ran and only inputs changed since */
    int fatal;              /* the model reported MODEL_FATAL: the step ends with fmi2Fatal */
    int terminate;          /* the model reported MODEL_TERMINATE: the step ends with fmi2Discard */
} Core;

struct Instance {
    const ModelDef *model;
    char *name;
    fmi2Type type;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
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

    /* constant tables derived from MODEL */
    int n_real_inputs;
    int *real_input_slot;    /* Real slot of each Real input */
    int *input_index;        /* per value reference: index into the Real inputs or -1 */
    int n_checked;
    int *checked_vr;         /* Real states and outputs, checked for finiteness after each step */

    /* scratch, not state */
    SolverWork *work;
    double *x;               /* continuous states, n_states: filled by gather_states before each use */
    double *dx;              /* n_states */
    double *input_values;    /* Real inputs as the master set them for the running doStep, n_real_inputs */
    double comm_point;       /* t_c: start of the running doStep [s] (origin of the input polynomials) */
    double *jac;             /* n_states x n_states */
    double *saved_reals;     /* n_reals: finite differences restore from here */
    double *fd_seed_base;    /* n_variables: known values around which to differentiate */
    double *fd_plus, *fd_minus; /* n_variables */
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
const char *state_name(int state);
/* 1 if the instance may make this call in its current state, else logs and returns 0. */
int check_state(Instance *inst, const char *function, unsigned allowed_mask);

/* instance.c */
Instance *instance_new(const char *name, fmi2Type type, fmi2CallbackLogger logger, fmi2ComponentEnvironment env,
                       int logging_on);
void instance_free(Instance *inst);
void instance_reset(Instance *inst); /* start values, time 0, state Instantiated */
const Variable *variable_of(const Instance *inst, fmi2ValueReference vr);
Initial effective_initial(const Variable *v);
/* NULL if `v` may be set in the current state, else the reason. */
const char *not_settable_reason(const Instance *inst, const Variable *v);
void gather_states(Instance *inst, double *x);       /* state slots -> x */
void scatter_states(Instance *inst, const double *x); /* x -> state slots */
void mark_dirty(Instance *inst);
/* After fmi2SetXXX of vr[0..nvr): outputs are stale; in Initialization Mode a changed
 * parameter or start value also means MODEL.initialize must run again. */
void note_set(Instance *inst, const fmi2ValueReference vr[], size_t nvr);
/* MODEL.initialize unless Core.initialized says it already ran; 0 on success (logs on failure). */
int run_initialize(Instance *inst, const char *function);
/* MODEL.outputs at the current time and states; 0 on success (no logging). */
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

/* step.c */
fmi2Status do_step(Instance *inst, double t, double H);
/* Model rhs/Jacobian with the input polynomials evaluated at time t (solver callbacks). */
int rhs_with_inputs(void *ctx, double t, const double *x, double *dx);
int jac_with_inputs(void *ctx, double t, const double *x, double *J);

/* derivative.c */
fmi2Status directional_derivative(Instance *inst, const fmi2ValueReference unknown[], size_t n_unknown,
                                  const fmi2ValueReference known[], size_t n_known, const double seed[],
                                  double result[]);

#endif
