/* oms_emachine: the electrical part of OMSimulator's DC-motor scene (component emachine_model of
 * tests/ssp/OpenModelica-OMSimulator/dcmotor) with the interface the scene gives it: the voltage
 * U and the shaft's speed w and angle phi in, the torque M and current I out, the parameters of
 * its resistor, inductor and emf.  The original (an OpenModelica export, Model Exchange only) is
 * not kept; these are our equations: an armature circuit (resistor, inductor, emf in series):
 *
 *   L i' = U - R_T i - k w,   R_T = R (1 + alpha (T - T_ref)),   M = k i,   I = i
 *
 * (the angle phi does not enter: the emf's support is fixed). */
#include "model.h"

enum {
    VR_SOLVER,
    VR_INTERNAL_STEP,
    VR_R,
    VR_T_REF,
    VR_ALPHA,
    VR_T,
    VR_L,
    VR_K,
    VR_U, /* 8 */
    VR_W, /* 9 */
    VR_PHI,
    VR_M,
    VR_I,
    VR_CURRENT, /* 13 */
    VR_DER_CURRENT,
    N_VARIABLES
};
enum { R_R = R_MODEL_START, R_T_REF, R_ALPHA, R_T, R_L, R_K, R_U, R_W, R_PHI, R_M, R_I, R_CURRENT, R_DER_CURRENT, N_REALS };

#define PARAMETER(name, slot, start, min, unit, description) \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, slot, start, NULL, min, INFINITY, unit, description, NO_STATE, NULL}
#define INPUT(name, slot, unit, description) \
    {name, T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define OUTPUT(name, slot, unit, description) \
    {name, T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, "13"}

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    PARAMETER("resistor.R", R_R, 0.5, 0.0, "Ohm", "Resistance at temperature T_ref"),
    PARAMETER("resistor.T_ref", R_T_REF, 300.15, 0.0, "K", "Reference temperature"),
    PARAMETER("resistor.alpha", R_ALPHA, 0.0, -INFINITY, "1/K",
              "Temperature coefficient of resistance (R_actual = R*(1 + alpha*(T - T_ref)))"),
    PARAMETER("resistor.T", R_T, 300.15, 0.0, "K", "Fixed device temperature"),
    PARAMETER("inductor.L", R_L, 0.001, 0.0, "H", "Inductance (> 0)"),
    PARAMETER("emf.k", R_K, 0.1, -INFINITY, "N.m/A", "Transformation coefficient"),
    INPUT("U", R_U, "V", "voltage across the armature"),
    INPUT("w", R_W, "rad/s", "speed of the shaft"),
    INPUT("phi", R_PHI, "rad", "angle of the shaft (does not enter the equations)"),
    OUTPUT("M", R_M, "N.m", "torque on the shaft: k i"),
    OUTPUT("I", R_I, "A", "armature current"),
    {"inductor.i", T_REAL, C_LOCAL, V_CONTINUOUS, I_EXACT, R_CURRENT, 0.0, NULL, -INFINITY, INFINITY, "A",
     "current through the inductor (state)", NO_STATE, NULL},
    {"der(inductor.i)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_CURRENT, 0.0, NULL, -INFINITY,
     INFINITY, "A/s", "derivative of inductor.i", VR_CURRENT, "8 9 13"},
};

static const int STATE_SLOTS[] = {R_CURRENT};
static const int DERIVATIVE_SLOTS[] = {R_DER_CURRENT};

static double resistance(const double *r)
{
    return r[R_R] * (1.0 + r[R_ALPHA] * (r[R_T] - r[R_T_REF]));
}

static ModelStatus initialize(Instance *inst)
{
    const double *r = model_reals(inst);
    if (!(r[R_L] > 0.0)) {
        model_log(inst, "logError", "oms_emachine: inductor.L = %g must be > 0", r[R_L]);
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    const double *r = model_reals(inst);
    (void)t;
    dx[0] = (r[R_U] - resistance(r) * x[0] - r[R_K] * r[R_W]) / r[R_L];
    return MODEL_OK;
}

static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J)
{
    const double *r = model_reals(inst);
    (void)t, (void)x;
    J[0] = -resistance(r) / r[R_L];
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x)
{
    double *r = model_reals(inst);
    (void)t;
    r[R_M] = r[R_K] * x[0];
    r[R_I] = x[0];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "oms_emachine",
    .guid = "{a24adad4-7e42-4fe4-9418-3b7b1541c793}",
    .description = "electrical part of the DC-Motor model: resistor, inductor and emf in series",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .me_only = 1,
    .default_step_size = 0.002,
    .n_states = 1,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = outputs,
    .autonomous = 1,
};
