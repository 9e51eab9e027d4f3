/* gain: y = K u, no state: an output that depends on its input alone (resampling tests). */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_K, VR_U, VR_Y, N_VARIABLES };
enum { R_K = R_MODEL_START, R_U, R_Y, N_REALS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"K", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_K, 2.0, NULL, -INFINITY, INFINITY, NULL, "gain", NO_STATE, NULL},
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U, 0.0, NULL, -INFINITY, INFINITY, NULL, "input", NO_STATE,
     NULL},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y, 0.0, NULL, -INFINITY, INFINITY, NULL, "K u",
     NO_STATE, "3"},
};

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    (void)x;
    double *r = model_reals(inst);
    r[R_Y] = r[R_K] * r[R_U];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "gain",
    .guid = "{c2d7a0e4-5f61-4b3a-9e28-7d4b1f0a6c53}",
    .description = "y = K u: an output that depends on its input alone (resampling tests)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_booleans = 0,
    .n_strings = 0,
    .n_states = 0,
    .state_slots = NULL,
    .derivative_slots = NULL,
    .initialize = NULL,
    .derivatives = NULL,
    .jacobian = NULL,
    .outputs = outputs,
};
