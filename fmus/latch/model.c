/* latch: holds the latest value of a discrete Int32 input and counts its changes, for discrete
 * signals passed between FMUs at events.  Its output next = min(latched + increment, limit) lets two
 * latches form a discrete cycle that counts up to `limit` (settles) or without end (limit beyond).
 *
 * Its event update latches the input: where u differs from `latched`, latched = u, changes + 1 and
 * t_latched = the event's time.  An FMU in FMI 3.0 Event Mode has a changed input set in Event Mode
 * and latches it there, at the time it changed (an input event); elsewhere (FMI 2.0, or no Event
 * Mode) a step event after each internal step latches it, one internal step late.  From latched = 0
 * the initial event iteration latches the input's start value (changes = 1 if it is not 0).
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_U, VR_LATCHED, VR_CHANGES, VR_T_LATCHED, VR_INCREMENT, VR_LIMIT, VR_NEXT,
       N_VARIABLES };

enum { R_T_LATCHED = R_MODEL_START, N_REALS };
enum { I_U = I_MODEL_START, I_LATCHED, I_CHANGES, I_INCREMENT, I_LIMIT, I_NEXT, N_INTEGERS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"u", T_INTEGER, C_INPUT, V_DISCRETE, I_DEFAULT, I_U, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "the value to latch", NO_STATE, NULL},
    {"latched", T_INTEGER, C_OUTPUT, V_DISCRETE, I_EXACT, I_LATCHED, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "u as latched at its latest change", NO_STATE, ""},
    {"changes", T_INTEGER, C_OUTPUT, V_DISCRETE, I_EXACT, I_CHANGES, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "number of changes of u latched", NO_STATE, ""},
    {"t_latched", T_REAL, C_OUTPUT, V_DISCRETE, I_EXACT, R_T_LATCHED, 0.0, NULL, -INFINITY, INFINITY, "s",
     "time of the latest change latched", NO_STATE, ""},
    {"increment", T_INTEGER, C_PARAMETER, V_FIXED, I_EXACT, I_INCREMENT, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "next = latched + increment, at most limit", NO_STATE, NULL},
    {"limit", T_INTEGER, C_PARAMETER, V_FIXED, I_EXACT, I_LIMIT, 1000000.0, NULL, -INFINITY, INFINITY, NULL,
     "the largest next", NO_STATE, NULL},
    {"next", T_INTEGER, C_OUTPUT, V_DISCRETE, I_CALCULATED, I_NEXT, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "min(latched + increment, limit)", NO_STATE, ""},
};

static ModelStatus outputs(Instance *inst, double t, const double *x)
{
    int *i = model_integers(inst);
    (void)t, (void)x;
    i[I_NEXT] = i[I_LATCHED] + i[I_INCREMENT] < i[I_LIMIT] ? i[I_LATCHED] + i[I_INCREMENT] : i[I_LIMIT];
    return MODEL_OK;
}

static ModelStatus update(Instance *inst, double t, double *x, EventUpdate *ev)
{
    int *i = model_integers(inst);
    (void)x;
    if (i[I_U] != i[I_LATCHED]) {
        i[I_LATCHED] = i[I_U];
        i[I_CHANGES]++;
        model_reals(inst)[R_T_LATCHED] = t;
        ev->changed = 1;
    }
    ev->next_event_time = INFINITY;
    return MODEL_OK;
}

static int step_event(Instance *inst, double t, const double *x)
{
    const int *i = model_integers(inst);
    (void)t, (void)x;
    return i[I_U] != i[I_LATCHED];
}

const ModelDef MODEL = {
    .identifier = "latch",
    .guid = "{3c7d2a91-5e48-4b0f-a6d3-81f9e2c4b057}",
    .description = "Latch: holds the latest value of a discrete Int32 input, counts its changes",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .outputs = outputs,
    .update = update,
    .step_event = step_event,
};
