/* dahlquist: the scalar test equation y' = lambda y, y(0) = y0.
 *
 * Exact solution y(t) = y0 exp(lambda t).  A fixed-step method with step h maps
 * y_n to R(lambda h) y_n, so the FMU checks solver order and stability limits.
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_LAMBDA, VR_Y0, VR_Y, VR_DER_Y, N_VARIABLES };

enum { R_LAMBDA = R_MODEL_START, R_Y0, R_Y, R_DER_Y, N_REALS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    {"lambda", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_LAMBDA, -1.0, NULL, -INFINITY, INFINITY, "1/s",
     "eigenvalue of the test equation", NO_STATE, NULL},
    {"y0", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_Y0, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "initial value y(0)", NO_STATE, NULL},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "state and output", NO_STATE, "4"},
    {"der(y)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_Y, 0.0, NULL, -INFINITY, INFINITY, "1/s",
     "derivative of y", VR_Y, "4"},
};

static const int STATE_SLOTS[] = {R_Y};
static const int DERIVATIVE_SLOTS[] = {R_DER_Y};

static ModelStatus initialize(Instance *inst)
{
    double *r = model_reals(inst);
    r[R_Y] = r[R_Y0];
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    (void)t;
    dx[0] = model_reals(inst)[R_LAMBDA] * x[0];
    return MODEL_OK;
}

static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J)
{
    (void)t, (void)x;
    J[0] = model_reals(inst)[R_LAMBDA];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "dahlquist",
    .guid = "{e2f3624c-49af-4936-b7b5-daa2c69e71d4}",
    .description = "Dahlquist test equation y' = lambda y",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_booleans = 0,
    .n_strings = 0,
    .n_states = 1,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = NULL,
};
