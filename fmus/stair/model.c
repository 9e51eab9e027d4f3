/* stair: a time-event counter.  The Integer output `counter` starts at 1 and grows by one at every
 * time event t = k period (k = 1, 2, ...): counter(t) = 1 + floor(t / period).  No continuous state.
 * When the counter reaches `last` (> 0) the model ends the simulation (terminateSimulation).
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_PERIOD, VR_COUNTER, VR_NEXT, VR_LAST, N_VARIABLES };

enum { R_PERIOD = R_MODEL_START, R_NEXT, N_REALS };
enum { I_COUNTER = I_MODEL_START, I_LAST, N_INTEGERS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"period", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_PERIOD, 1.0, NULL, 0.0, INFINITY, "s",
     "time between two steps of the counter", NO_STATE, NULL},
    {"counter", T_INTEGER, C_OUTPUT, V_DISCRETE, I_EXACT, I_COUNTER, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "1 + the number of periods passed", NO_STATE, ""},
    {"next_time", T_REAL, C_LOCAL, V_DISCRETE, I_CALCULATED, R_NEXT, 0.0, NULL, -INFINITY, INFINITY, "s",
     "time of the next step of the counter", NO_STATE, NULL},
    {"last", T_INTEGER, C_PARAMETER, V_FIXED, I_EXACT, I_LAST, 0.0, NULL, 0.0, INFINITY, NULL,
     "the counter at which the model ends the simulation; 0: never", NO_STATE, NULL},
};

static ModelStatus initialize(Instance *inst)
{
    double *r = model_reals(inst);
    r[R_NEXT] = r[R_PERIOD] * (double)model_integers(inst)[I_COUNTER];
    return MODEL_OK;
}

static ModelStatus update(Instance *inst, double t, double *x, EventUpdate *ev)
{
    double *r = model_reals(inst);
    int *counter = &model_integers(inst)[I_COUNTER];
    (void)x;
    if (t >= r[R_NEXT] - 1e-9 * r[R_PERIOD]) { /* the time event (an importer may meet it to rounding) */
        ++*counter;
        r[R_NEXT] = r[R_PERIOD] * (double)*counter; /* from the integer: no drift */
        ev->changed = 1;
    }
    ev->next_event_time = r[R_NEXT];
    return *counter == model_integers(inst)[I_LAST] ? MODEL_TERMINATE : MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "stair",
    .guid = "{8a0f6c2e-2b6d-4d5e-9f1a-7c3e2d9b4a10}",
    .description = "Stair: an Integer counter stepped by time events every period",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .initialize = initialize,
    .update = update,
};
