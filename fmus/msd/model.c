/* msd: a mass-spring-damper with a coupling spring-damper towards another body.
 *
 *   m x'' = -c x - d x' + F - F_c,        F_c = cc (x - x_in) + dc (v - v_in)
 *
 * F is an external force on this mass.  F_c is the force the coupling exerts on
 * the OTHER body (at position x_in, velocity v_in); this mass feels -F_c.  F_c
 * depends directly on the inputs x_in, v_in (direct feedthrough).
 *
 * Two-mass oscillator (numerics-facts.md):
 *   m1 x1'' = -c1 x1 - d1 x1' + F,  m2 x2'' = -c2 x2 - d2 x2' - F,  F = cc (x2 - x1) + dc (x2' - x1')
 * FMU 1 = msd with cc = dc = 0, input F, outputs x, v              (mass 1)
 * FMU 2 = msd with cc, dc of the coupling, inputs x_in = x1, v_in = v1, output F_c (mass 2)
 * Then F_c of FMU 2 = cc (x2 - x1) + dc (v2 - v1) = F: connect it to F of FMU 1,
 * and FMU 2's own equation reads m2 x2'' = -c2 x2 - d2 x2' - F as required.
 */
#include "model.h"

enum {
    VR_SOLVER,
    VR_INTERNAL_STEP,
    VR_M,
    VR_C,
    VR_D,
    VR_CC,
    VR_DC,
    VR_X0,
    VR_V0,
    VR_F,
    VR_X_IN,
    VR_V_IN,
    VR_X,
    VR_V,
    VR_F_C,
    VR_DER_X,
    VR_DER_V,
    N_VARIABLES
};

enum { R_M = R_MODEL_START, R_C, R_D, R_CC, R_DC, R_X0, R_V0, R_F, R_X_IN, R_V_IN, R_X, R_V, R_F_C, R_DER_X, R_DER_V, N_REALS };

#define PARAMETER(name, slot, start, min, unit, description) \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, slot, start, NULL, min, INFINITY, unit, description, NO_STATE, NULL}
#define INPUT(name, slot, unit, description) \
    {name, T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    PARAMETER("m", R_M, 1.0, 0.0, "kg", "mass (must be > 0)"),
    PARAMETER("c", R_C, 1.0, -INFINITY, "N/m", "spring constant to the ground"),
    PARAMETER("d", R_D, 1.0, -INFINITY, "N.s/m", "damping constant to the ground"),
    PARAMETER("cc", R_CC, 0.0, -INFINITY, "N/m", "coupling spring constant towards x_in"),
    PARAMETER("dc", R_DC, 0.0, -INFINITY, "N.s/m", "coupling damping constant towards v_in"),
    PARAMETER("x0", R_X0, 0.0, -INFINITY, "m", "initial position"),
    PARAMETER("v0", R_V0, 0.0, -INFINITY, "m/s", "initial velocity"),
    INPUT("F", R_F, "N", "external force on this mass"),
    INPUT("x_in", R_X_IN, "m", "position of the other body (coupling)"),
    INPUT("v_in", R_V_IN, "m/s", "velocity of the other body (coupling)"),
    {"x", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_X, 0.0, NULL, -INFINITY, INFINITY, "m",
     "position (state)", NO_STATE, "12"},
    {"v", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_V, 0.0, NULL, -INFINITY, INFINITY, "m/s",
     "velocity (state)", NO_STATE, "13"},
    {"F_c", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_F_C, 0.0, NULL, -INFINITY, INFINITY, "N",
     "coupling force on the other body: cc (x - x_in) + dc (v - v_in)", NO_STATE, "10 11 12 13"},
    {"der(x)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_X, 0.0, NULL, -INFINITY, INFINITY, "m/s",
     "derivative of x", VR_X, "13"},
    {"der(v)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_V, 0.0, NULL, -INFINITY, INFINITY, "m/s2",
     "derivative of v", VR_V, "9 10 11 12 13"},
};

static const int STATE_SLOTS[] = {R_X, R_V};
static const int DERIVATIVE_SLOTS[] = {R_DER_X, R_DER_V};

static ModelStatus initialize(Instance *inst)
{
    double *r = model_reals(inst);
    if (!(r[R_M] > 0.0)) {
        model_log(inst, "logError", "msd: mass m = %g must be > 0", r[R_M]);
        return MODEL_ERROR;
    }
    r[R_X] = r[R_X0];
    r[R_V] = r[R_V0];
    return MODEL_OK;
}

static double coupling_force(const double *r, const double *x)
{
    return r[R_CC] * (x[0] - r[R_X_IN]) + r[R_DC] * (x[1] - r[R_V_IN]);
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    const double *r = model_reals(inst);
    (void)t;
    dx[0] = x[1];
    dx[1] = (-r[R_C] * x[0] - r[R_D] * x[1] + r[R_F] - coupling_force(r, x)) / r[R_M];
    return MODEL_OK;
}

static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J)
{
    const double *r = model_reals(inst);
    (void)t, (void)x;
    J[0] = 0.0;
    J[1] = 1.0;
    J[2] = -(r[R_C] + r[R_CC]) / r[R_M];
    J[3] = -(r[R_D] + r[R_DC]) / r[R_M];
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x)
{
    double *r = model_reals(inst);
    (void)t;
    r[R_F_C] = coupling_force(r, x);
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "msd",
    .guid = "{c1a5f5d7-d091-45a2-97b3-8940c8e95028}",
    .description = "Mass-spring-damper with a coupling spring-damper (two-mass oscillator building block)",
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
    .outputs = outputs,
};
