/* discrete: a first-order state driven by Integer and Boolean inputs, with Integer and Boolean
 * outputs, for testing discrete coupling (signals held between communication points).
 *
 *   x' = on_in ? (n_in + 1) rate : -rate x + u
 *   n  = floor(x / quantum)   (Integer output)
 *   on = x > threshold        (Boolean output)
 *
 * Its outputs depend on the state only, so a master sets each input once per step.
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_RATE, VR_QUANTUM, VR_THRESHOLD, VR_N_IN, VR_ON_IN, VR_U,
       VR_X, VR_N, VR_ON, VR_DER_X, N_VARIABLES };

enum { R_RATE = R_MODEL_START, R_QUANTUM, R_THRESHOLD, R_U, R_X, R_DER_X, N_REALS };
enum { I_N_IN = I_MODEL_START, I_N, N_INTEGERS };
enum { B_ON_IN, B_ON, N_BOOLEANS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"rate", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_RATE, 1.0, NULL, -INFINITY, INFINITY, "1/s",
     "rate of the state", NO_STATE, NULL},
    {"quantum", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_QUANTUM, 0.25, NULL, 1e-300, INFINITY, NULL,
     "the Integer output counts quanta of the state", NO_STATE, NULL},
    {"threshold", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_THRESHOLD, 0.5, NULL, -INFINITY, INFINITY, NULL,
     "the Boolean output is on above this state", NO_STATE, NULL},
    {"n_in", T_INTEGER, C_INPUT, V_DISCRETE, I_DEFAULT, I_N_IN, 0, NULL, -INFINITY, INFINITY, NULL,
     "Integer input: the state grows by (n_in + 1) rate while on_in", NO_STATE, NULL},
    {"on_in", T_BOOLEAN, C_INPUT, V_DISCRETE, I_DEFAULT, B_ON_IN, 0, NULL, 0, 1, NULL,
     "Boolean input: growth (true) or decay (false)", NO_STATE, NULL},
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Real input added while decaying", NO_STATE, NULL},
    {"x", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_X, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "state and output", NO_STATE, ""},
    {"n", T_INTEGER, C_OUTPUT, V_DISCRETE, I_CALCULATED, I_N, 0, NULL, -INFINITY, INFINITY, NULL,
     "floor(x / quantum)", NO_STATE, "8"},
    {"on", T_BOOLEAN, C_OUTPUT, V_DISCRETE, I_CALCULATED, B_ON, 0, NULL, 0, 1, NULL,
     "x > threshold", NO_STATE, "8"},
    {"der(x)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_X, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "derivative of x", VR_X, NULL},
};

static const int STATE_SLOTS[] = {R_X};
static const int DERIVATIVE_SLOTS[] = {R_DER_X};

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx) {
    (void)t;
    const double *r = model_reals(inst);
    if (model_booleans(inst)[B_ON_IN])
        dx[0] = (double)(model_integers(inst)[I_N_IN] + 1) * r[R_RATE];
    else
        dx[0] = -r[R_RATE] * x[0] + r[R_U];
    return MODEL_OK;
}

static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J) {
    (void)t;
    (void)x;
    J[0] = model_booleans(inst)[B_ON_IN] ? 0.0 : -model_reals(inst)[R_RATE];
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    const double *r = model_reals(inst);
    model_integers(inst)[I_N] = (int)floor(x[0] / r[R_QUANTUM]);
    model_booleans(inst)[B_ON] = x[0] > r[R_THRESHOLD];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "discrete",
    .guid = "{9b3e51d2-7a4c-4f0e-b8d6-2c1a5e7f9034}",
    .description = "A state driven by Integer and Boolean inputs, with Integer and Boolean outputs (discrete coupling tests)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .n_booleans = N_BOOLEANS,
    .n_strings = 0,
    .n_states = 1,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = NULL,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = outputs,
};
