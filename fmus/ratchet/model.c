/* ratchet: step events.  x' = rate; after an integrator step that leaves x >= 1 the model asks for
 * an event (fmi2/3CompletedIntegratorStep's enterEventMode), where x := x - 1 and the Integer output
 * `count` grows by one.  With rate 1 and a step that divides 1 exactly (a power of two), x reaches
 * 1 exactly at t = 1, 2, ...: count(t) = floor(t), x(t) = t - floor(t) on the step grid.
 * `drop` (default 1) is what an event takes from x: with 0 the event iteration never ends.
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_X, VR_DER_X, VR_RATE, VR_COUNT, VR_DROP, N_VARIABLES };

enum { R_X = R_MODEL_START, R_DER_X, R_RATE, R_DROP, N_REALS };
enum { I_COUNT = I_MODEL_START, N_INTEGERS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"x", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_X, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "state and output", NO_STATE, "2"},
    {"der(x)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_X, 0.0, NULL, -INFINITY, INFINITY, "1/s",
     "derivative of x", VR_X, ""},
    {"rate", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_RATE, 1.0, NULL, -INFINITY, INFINITY, "1/s",
     "slope of x", NO_STATE, NULL},
    {"count", T_INTEGER, C_OUTPUT, V_DISCRETE, I_EXACT, I_COUNT, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "events so far", NO_STATE, ""},
    {"drop", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_DROP, 1.0, NULL, 0.0, INFINITY, NULL,
     "taken from x at an event", NO_STATE, NULL},
};

static const int STATE_SLOTS[] = {R_X};
static const int DERIVATIVE_SLOTS[] = {R_DER_X};

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    (void)t, (void)x;
    dx[0] = model_reals(inst)[R_RATE];
    return MODEL_OK;
}

static int step_event(Instance *inst, double t, const double *x)
{
    (void)inst, (void)t;
    return x[0] >= 1.0;
}

static ModelStatus update(Instance *inst, double t, double *x, EventUpdate *ev)
{
    (void)t;
    if (x[0] >= 1.0) {
        x[0] -= model_reals(inst)[R_DROP];
        model_integers(inst)[I_COUNT]++;
        ev->changed = 1;
    }
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "ratchet",
    .guid = "{b2c4d6e8-1a3b-4c5d-9e7f-2468ace0bd13}",
    .description = "Ratchet: step events, x' = rate and x := x - 1, count += 1 once x >= 1",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .n_states = 1,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .derivatives = derivatives,
    .autonomous = 1,
    .step_event = step_event,
    .update = update,
};
