/* oms_edrive_mass: the mechanical part of OMSimulator's DC-motor scene (component edrive_mass of
 * tests/ssp/OpenModelica-OMSimulator/dcmotor) with the interface the scene gives it: the torques
 * M_A (motor) and M_B (load) in, the angles and speeds of both flanges out, the parameters
 * inertia.J and damper.d.  The original (an OpenModelica export, Model Exchange only) is not
 * kept; these are our equations: one rigid inertia whose two flanges A and B turn together, with
 * a viscous damper to the ground (bearing friction):
 *
 *   phi' = w,    J w' = M_A + M_B - d w,    phiA = phiB = phi,  wA = wB = w
 */
#include "model.h"

enum {
    VR_SOLVER,
    VR_INTERNAL_STEP,
    VR_J,
    VR_D,
    VR_M_A,
    VR_M_B,
    VR_PHI_A,
    VR_W_A,
    VR_PHI_B,
    VR_W_B,
    VR_PHI, /* 10 */
    VR_W,   /* 11 */
    VR_DER_PHI,
    VR_DER_W,
    N_VARIABLES
};
enum { R_J = R_MODEL_START, R_D, R_M_A, R_M_B, R_PHI_A, R_W_A, R_PHI_B, R_W_B, R_PHI, R_W, R_DER_PHI, R_DER_W, N_REALS };

#define PARAMETER(name, slot, start, min, unit, description) \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, slot, start, NULL, min, INFINITY, unit, description, NO_STATE, NULL}
#define INPUT(name, slot, unit, description) \
    {name, T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define OUTPUT(name, slot, unit, description, dependencies) \
    {name, T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, dependencies}
#define STATE(name, slot, unit, description) \
    {name, T_REAL, C_LOCAL, V_CONTINUOUS, I_EXACT, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    PARAMETER("inertia.J", R_J, 0.002, 0.0, "kg.m2", "Moment of inertia (> 0)"),
    PARAMETER("damper.d", R_D, 0.001, 0.0, "N.m.s/rad", "Damping constant (to the ground)"),
    INPUT("M_A", R_M_A, "N.m", "torque on flange A (the motor's)"),
    INPUT("M_B", R_M_B, "N.m", "torque on flange B (the load's)"),
    OUTPUT("phiA", R_PHI_A, "rad", "angle of flange A", "10"),
    OUTPUT("wA", R_W_A, "rad/s", "speed of flange A", "11"),
    OUTPUT("phiB", R_PHI_B, "rad", "angle of flange B", "10"),
    OUTPUT("wB", R_W_B, "rad/s", "speed of flange B", "11"),
    STATE("inertia.phi", R_PHI, "rad", "angle of the inertia (state)"),
    STATE("inertia.w", R_W, "rad/s", "speed of the inertia (state)"),
    {"der(inertia.phi)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_PHI, 0.0, NULL, -INFINITY, INFINITY,
     "rad/s", "derivative of inertia.phi", VR_PHI, "11"},
    {"der(inertia.w)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_W, 0.0, NULL, -INFINITY, INFINITY,
     "rad/s2", "derivative of inertia.w", VR_W, "4 5 11"},
};

static const int STATE_SLOTS[] = {R_PHI, R_W};
static const int DERIVATIVE_SLOTS[] = {R_DER_PHI, R_DER_W};

static ModelStatus initialize(Instance *inst)
{
    const double *r = model_reals(inst);
    if (!(r[R_J] > 0.0)) {
        model_log(inst, "logError", "oms_edrive_mass: inertia.J = %g must be > 0", r[R_J]);
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    const double *r = model_reals(inst);
    (void)t;
    dx[0] = x[1];
    dx[1] = (r[R_M_A] + r[R_M_B] - r[R_D] * x[1]) / r[R_J];
    return MODEL_OK;
}

static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J)
{
    const double *r = model_reals(inst);
    (void)t, (void)x;
    J[0] = 0.0;
    J[1] = 1.0;
    J[2] = 0.0;
    J[3] = -r[R_D] / r[R_J];
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x)
{
    double *r = model_reals(inst);
    (void)t;
    r[R_PHI_A] = r[R_PHI_B] = x[0];
    r[R_W_A] = r[R_W_B] = x[1];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "oms_edrive_mass",
    .guid = "{4cd3efb3-7472-4130-9986-49f210b87492}",
    .description = "Mechanical part of the DC motor model: a rigid inertia with a damper to the ground",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .me_only = 1,
    .default_step_size = 0.002,
    .n_states = 2,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = outputs,
    .autonomous = 1,
};
