/* vanderpol: the Van der Pol oscillator, a nonlinear system without a closed form.
 *
 *   x1' = x2,    x2' = mu (1 - x1^2) x2 - x1
 *
 * Parameters mu and the initial states x1_0, x2_0; outputs the states.  For mu of order one the
 * solution approaches the limit cycle smoothly; for large mu it is stiff.  The Jacobian is given,
 * so the semi-implicit methods use it (FMI directional derivatives come from it too).
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_MU, VR_X1_0, VR_X2_0, VR_X1, VR_X2, VR_DER_X1, VR_DER_X2, N_VARIABLES };

enum { R_MU = R_MODEL_START, R_X1_0, R_X2_0, R_X1, R_X2, R_DER_X1, R_DER_X2, N_REALS };

#define PARAMETER(name, slot, start, min, description) \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, slot, start, NULL, min, INFINITY, NULL, description, NO_STATE, NULL}

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    PARAMETER("mu", R_MU, 1.0, 0.0, "damping parameter (>= 0)"),
    PARAMETER("x1_0", R_X1_0, 2.0, -INFINITY, "initial x1"),
    PARAMETER("x2_0", R_X2_0, 0.0, -INFINITY, "initial x2"),
    {"x1", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_X1, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "first state", NO_STATE, "5"},
    {"x2", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_X2, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "second state: the derivative of x1", NO_STATE, "6"},
    {"der(x1)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_X1, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "derivative of x1", VR_X1, "6"},
    {"der(x2)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_X2, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "derivative of x2", VR_X2, "5 6"},
};

static const int STATE_SLOTS[] = {R_X1, R_X2};
static const int DERIVATIVE_SLOTS[] = {R_DER_X1, R_DER_X2};

static ModelStatus initialize(Instance *inst)
{
    double *r = model_reals(inst);
    r[R_X1] = r[R_X1_0];
    r[R_X2] = r[R_X2_0];
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    const double mu = model_reals(inst)[R_MU];
    (void)t;
    dx[0] = x[1];
    dx[1] = mu * (1.0 - x[0] * x[0]) * x[1] - x[0];
    return MODEL_OK;
}

/* J[i * 2 + j] = d x_i' / d x_j */
static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J)
{
    const double mu = model_reals(inst)[R_MU];
    (void)t;
    J[0] = 0.0;
    J[1] = 1.0;
    J[2] = -2.0 * mu * x[0] * x[1] - 1.0;
    J[3] = mu * (1.0 - x[0] * x[0]);
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "vanderpol",
    .guid = "{5d2c8a41-7e3b-4f90-b6a1-2c9e8d4f7a63}",
    .description = "Van der Pol oscillator (no closed form; solver accuracy against a tight reference)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_booleans = 0,
    .n_strings = 0,
    .n_states = 2,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = NULL,
};
