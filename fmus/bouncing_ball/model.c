/* bouncing_ball: a ball falling under gravity, bouncing on the ground (a state event).
 *
 * h' = v, v' = -g; when h reaches 0 falling, v := -e v (and h := DBL_MIN, just above the ground, so
 * that the indicator h starts the next flight in the domain h > 0).  From h(0) = h0, v(0) = 0 the
 * bounces come at t_1 = sqrt(2 h0 / g), t_{k+1} = t_k + 2 e^k sqrt(2 g h0) / g, and the flight after
 * bounce k reaches e^(2k) h0.  Between bounces h is a quadratic in t: RK4, AB2 and AB3 integrate it
 * exactly, so their bounce times differ from the closed form by the event location alone.
 * A bounce that leaves the ball slower than v_min puts it to rest (h' = v' = 0, no more events): the
 * bounces would otherwise accumulate at t1 (1 + e) / (1 - e) (a Zeno point).  The event indicator
 * is the variable `z`: h in flight, 1 at rest.
 */
#include <float.h>

#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_H, VR_DER_H, VR_V, VR_DER_V, VR_G, VR_E, VR_H0, VR_V_MIN, VR_Z, VR_RESTING,
       N_VARIABLES };

enum { R_H = R_MODEL_START, R_DER_H, R_V, R_DER_V, R_G, R_E, R_H0, R_V_MIN, R_Z, N_REALS };
enum { B_RESTING, N_BOOLEANS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    {"h", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_H, 0.0, NULL, -INFINITY, INFINITY, "m",
     "height of the ball", NO_STATE, "2"},
    {"der(h)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_H, 0.0, NULL, -INFINITY, INFINITY, "m/s",
     "derivative of h", VR_H, "4"},
    {"v", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_V, 0.0, NULL, -INFINITY, INFINITY, "m/s",
     "velocity of the ball", NO_STATE, "4"},
    {"der(v)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_V, 0.0, NULL, -INFINITY, INFINITY, "m/s2",
     "derivative of v", VR_V, ""},
    {"g", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_G, 9.81, NULL, 0.0, INFINITY, "m/s2",
     "gravity acceleration", NO_STATE, NULL},
    {"e", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_E, 0.7, NULL, 0.0, 1.0, NULL,
     "coefficient of restitution", NO_STATE, NULL},
    {"h0", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_H0, 1.0, NULL, 0.0, INFINITY, "m",
     "initial height", NO_STATE, NULL},
    {"v_min", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_V_MIN, 0.1, NULL, 0.0, INFINITY, "m/s",
     "a bounce slower than this puts the ball to rest", NO_STATE, NULL},
    {"z", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_Z, 0.0, NULL, -INFINITY, INFINITY, "m",
     "the event indicator: h in flight, 1 at rest", NO_STATE, NULL},
    {"resting", T_BOOLEAN, C_LOCAL, V_DISCRETE, I_EXACT, B_RESTING, 0.0, NULL, 0.0, 1.0, NULL,
     "the ball lies on the ground", NO_STATE, NULL},
};

static const int STATE_SLOTS[] = {R_H, R_V};
static const int DERIVATIVE_SLOTS[] = {R_DER_H, R_DER_V};
static const int EVENT_INDICATOR_VRS[] = {VR_Z};

static ModelStatus initialize(Instance *inst)
{
    double *r = model_reals(inst);
    r[R_H] = r[R_H0];
    r[R_V] = 0.0;
    return MODEL_OK;
}

static int resting(Instance *inst)
{
    return model_booleans(inst)[B_RESTING];
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    (void)t;
    dx[0] = resting(inst) ? 0.0 : x[1];
    dx[1] = resting(inst) ? 0.0 : -model_reals(inst)[R_G];
    return MODEL_OK;
}

static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J)
{
    (void)t, (void)x;
    J[0] = 0.0, J[1] = resting(inst) ? 0.0 : 1.0, J[2] = 0.0, J[3] = 0.0;
    return MODEL_OK;
}

static ModelStatus event_indicators(Instance *inst, double t, const double *x, double *z)
{
    (void)t;
    z[0] = resting(inst) ? 1.0 : x[0];
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x)
{
    return event_indicators(inst, t, x, &model_reals(inst)[R_Z]);
}

static ModelStatus update(Instance *inst, double t, double *x, EventUpdate *ev)
{
    (void)t;
    const double *r = model_reals(inst);
    if (!resting(inst) && x[0] <= 0.0 && x[1] < 0.0) { /* on the ground, falling: the bounce */
        x[0] = DBL_MIN;
        x[1] = -r[R_E] * x[1];
        if (x[1] < r[R_V_MIN]) { /* too slow to take off again */
            x[1] = 0.0;
            model_booleans(inst)[B_RESTING] = 1;
        }
        ev->changed = 1;
    }
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "bouncing_ball",
    .guid = "{3c0c51a6-7d0e-4f0b-9a53-5b1de1b7c2a4}",
    .description = "Bouncing ball: a state event at h = 0, v := -e v",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_booleans = N_BOOLEANS,
    .n_states = 2,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = outputs,
    .autonomous = 1,
    .n_event_indicators = 1,
    .event_indicator_vrs = EVENT_INDICATOR_VRS,
    .event_indicators = event_indicators,
    .update = update,
};
