/* cubic: y = a u^3 + b u, no state: a nonlinear output that depends on its input alone (the
 * algebraic-loop tests: a loop through it needs Newton's iterations, not one step). */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_A, VR_B, VR_U, VR_Y, N_VARIABLES };
enum { R_A = R_MODEL_START, R_B, R_U, R_Y, N_REALS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"a", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_A, 1.0, NULL, -INFINITY, INFINITY, NULL, "cubic coefficient",
     NO_STATE, NULL},
    {"b", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_B, 0.0, NULL, -INFINITY, INFINITY, NULL, "linear coefficient",
     NO_STATE, NULL},
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U, 0.0, NULL, -INFINITY, INFINITY, NULL, "input", NO_STATE,
     NULL},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y, 0.0, NULL, -INFINITY, INFINITY, NULL, "a u^3 + b u",
     NO_STATE, "4"},
};

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    (void)x;
    double *r = model_reals(inst);
    const double u = r[R_U];
    r[R_Y] = r[R_A] * u * u * u + r[R_B] * u;
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "cubic",
    .guid = "{5b0e7c1a-2f8d-4e63-a9b4-0d6c3e8f1a27}",
    .description = "y = a u^3 + b u: a nonlinear output that depends on its input alone (algebraic-loop tests)",
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
