/* nonlinear: a smooth nonlinear, non-autonomous 2-D system with a closed-form solution,
 * for measuring the order of convergence of the solvers.
 *
 *   x' = -a x s - w(t) y,    y' = -a y s + w(t) x,    s = x^2 + y^2,   w(t) = omega (1 + t)
 *
 * In polar form r' = -a r^3 and theta' = w(t), so with r0, theta0 at t = 0:
 *   r(t) = r0 / sqrt(1 + 2 a r0^2 t),   theta(t) = theta0 + omega (t + t^2 / 2),
 *   x = r cos(theta),   y = r sin(theta).
 * The Jacobian is full (coupled through s and w), so the semi-implicit methods
 * exercise the dense LU with pivoting.
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_OMEGA, VR_A, VR_X, VR_Y, VR_DER_X, VR_DER_Y, N_VARIABLES };

enum { R_OMEGA = R_MODEL_START, R_A, R_X, R_Y, R_DER_X, R_DER_Y, N_REALS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    {"omega", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_OMEGA, 1.0, NULL, -INFINITY, INFINITY, "rad/s",
     "angular rate at t = 0; the rate grows as omega (1 + t)", NO_STATE, NULL},
    {"a", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_A, 1.0, NULL, 0, INFINITY, "1/s",
     "radial decay coefficient: r' = -a r^3", NO_STATE, NULL},
    {"x", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_X, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "first state and output", NO_STATE, ""},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_Y, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "second state and output", NO_STATE, ""},
    {"der(x)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_X, 0.0, NULL, -INFINITY, INFINITY, "1/s",
     "derivative of x", VR_X, NULL},
    {"der(y)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_Y, 0.0, NULL, -INFINITY, INFINITY, "1/s",
     "derivative of y", VR_Y, NULL},
};

static const int STATE_SLOTS[] = {R_X, R_Y};
static const int DERIVATIVE_SLOTS[] = {R_DER_X, R_DER_Y};

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    const double *r = model_reals(inst);
    double w = r[R_OMEGA] * (1.0 + t);
    double s = x[0] * x[0] + x[1] * x[1];
    dx[0] = -r[R_A] * x[0] * s - w * x[1];
    dx[1] = -r[R_A] * x[1] * s + w * x[0];
    return MODEL_OK;
}

static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J)
{
    const double *r = model_reals(inst);
    double a = r[R_A];
    double w = r[R_OMEGA] * (1.0 + t);
    double s = x[0] * x[0] + x[1] * x[1];
    J[0] = -a * (s + 2.0 * x[0] * x[0]);
    J[1] = -2.0 * a * x[0] * x[1] - w;
    J[2] = -2.0 * a * x[0] * x[1] + w;
    J[3] = -a * (s + 2.0 * x[1] * x[1]);
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "nonlinear",
    .guid = "{9b0e3f52-1c7a-4d6e-8f21-5a3c9d7e0b14}",
    .description = "Nonlinear non-autonomous 2-D system with a closed-form solution (solver order tests)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_booleans = 0,
    .n_strings = 0,
    .n_states = 2,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = NULL,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = NULL,
};
