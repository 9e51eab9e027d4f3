/* kicked: a decay kicked by time events.  y' = -y between the events t = k period (k = 1, 2, ...),
 * where y := y + kick.  From y(0) = 1 with period 1 and kick 1: y(t) = e^-(t - k) sum_{i=0..k} e^-i
 * for k <= t < k + 1.  The kick makes f jump: a multistep method that kept its history across it
 * would lose its order (the history restarts after every event).
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_Y, VR_DER_Y, VR_PERIOD, VR_KICK, VR_NEXT, N_VARIABLES };

enum { R_Y = R_MODEL_START, R_DER_Y, R_PERIOD, R_KICK, R_NEXT, N_REALS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_AB3, 0.0),
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_Y, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "state and output", NO_STATE, "2"},
    {"der(y)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_Y, 0.0, NULL, -INFINITY, INFINITY, "1/s",
     "derivative of y", VR_Y, "2"},
    {"period", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_PERIOD, 1.0, NULL, 0.0, INFINITY, "s",
     "time between two kicks", NO_STATE, NULL},
    {"kick", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_KICK, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "added to y at every kick", NO_STATE, NULL},
    {"next_time", T_REAL, C_LOCAL, V_DISCRETE, I_CALCULATED, R_NEXT, 0.0, NULL, -INFINITY, INFINITY, "s",
     "time of the next kick", NO_STATE, NULL},
};

static const int STATE_SLOTS[] = {R_Y};
static const int DERIVATIVE_SLOTS[] = {R_DER_Y};

static ModelStatus initialize(Instance *inst)
{
    double *r = model_reals(inst);
    r[R_NEXT] = r[R_PERIOD];
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    (void)inst, (void)t;
    dx[0] = -x[0];
    return MODEL_OK;
}

static ModelStatus update(Instance *inst, double t, double *x, EventUpdate *ev)
{
    double *r = model_reals(inst);
    if (t >= r[R_NEXT] - 1e-9 * r[R_PERIOD]) { /* the time event (an importer may meet it to rounding) */
        x[0] += r[R_KICK];
        r[R_NEXT] = r[R_PERIOD] * (nearbyint(t / r[R_PERIOD]) + 1.0);
        ev->changed = 1;
    }
    ev->next_event_time = r[R_NEXT];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "kicked",
    .guid = "{5d7e3b90-1c4a-4e2f-8b6d-0a9c1e2f3b47}",
    .description = "Kicked decay: y' = -y, y := y + kick at every time event t = k period",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_states = 1,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .autonomous = 1,
    .update = update,
};
