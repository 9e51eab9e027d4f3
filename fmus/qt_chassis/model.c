/* qt_chassis: the chassis of ecos's quarter truck (a 20-sim bond-graph export, "chassis"), with the
 * original's names for its parameters, input, outputs and states, and its equations:
 *
 *   v = I1.moment / I1.mChassis                       chassis velocity
 *   p.e = C.kChassis C.zDelta + R.dChassis (p.f - v)  suspension force (spring + damper)
 *   C.zDelta' = p.f - v                               suspension compression; p.f: wheel velocity
 *   I1.moment' = p.e - Se1.mChassis g                 momentum: suspension force and weight
 *   I1.zChassis' = QSensor.q' = v                     height (QSensor.q is the output zChassis)
 *
 * starting from static equilibrium: C.zDelta = C.mChassis g / C.kChassis (the original computes
 * C.zDeltaInit so at initialization, whatever its start value), at rest, at height 1 m.  The
 * output p.e depends directly on the input p.f, and like the original's the description declares
 * no dependencies (FMI 2.0: every output may depend on every input).  The original integrates by
 * RK4 with steps of at most 1 ms inside a communication step; here RK4 with one step per
 * communication step (internal_step 0; set internal_step for more). */
#include "model.h"

#define G_N 9.80665 /* m/s2, 20-sim's g_n */

enum {
    VR_SOLVER,
    VR_INTERNAL_STEP,
    VR_C_M,
    VR_C_K,
    VR_I1_M,
    VR_R_D,
    VR_SE1_M,
    VR_C_ZDELTA_INIT,
    VR_I1_MOMENT_INITIAL,
    VR_I1_ZCHASSIS_INIT,
    VR_P_E,
    VR_P_F,
    VR_ZCHASSIS,
    VR_C_ZDELTA,
    VR_I1_MOMENT,
    VR_I1_ZCHASSIS,
    VR_QSENSOR_Q,
    VR_C_P_F,
    VR_I1_P_E,
    VR_I1_P_F,
    VR_QSENSOR_P1_F,
    N_VARIABLES
};
enum {
    R_C_M = R_MODEL_START,
    R_C_K,
    R_I1_M,
    R_R_D,
    R_SE1_M,
    R_C_ZDELTA_INIT,
    R_I1_MOMENT_INITIAL,
    R_I1_ZCHASSIS_INIT,
    R_P_E,
    R_P_F,
    R_ZCHASSIS,
    R_C_ZDELTA,
    R_I1_MOMENT,
    R_I1_ZCHASSIS,
    R_QSENSOR_Q,
    R_C_P_F,
    R_I1_P_E,
    R_I1_P_F,
    R_QSENSOR_P1_F,
    N_REALS
};

#define TUNABLE(name, slot, start, unit, description) \
    {name, T_REAL, C_PARAMETER, V_TUNABLE, I_EXACT, slot, start, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define FIXED(name, slot, start, unit, description) \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, slot, start, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define STATE(name, slot, unit, description) \
    {name, T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define RATE(name, slot, state, unit, description) \
    {name, T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, state, NULL}

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    TUNABLE("C.mChassis", R_C_M, 400.0, "kg", "chassis mass in the initial spring compression"),
    TUNABLE("C.kChassis", R_C_K, 15000.0, "N/m", "suspension stiffness"),
    TUNABLE("I1.mChassis", R_I1_M, 400.0, "kg", "chassis mass (inertia)"),
    TUNABLE("R.dChassis", R_R_D, 1000.0, "N.s/m", "suspension damping"),
    TUNABLE("Se1.mChassis", R_SE1_M, 400.0, "kg", "chassis mass (weight)"),
    FIXED("C.zDeltaInit", R_C_ZDELTA_INIT, 0.261510666666667, "m",
          "initial compression: computed at initialization as C.mChassis g / C.kChassis"),
    FIXED("I1.moment_initial", R_I1_MOMENT_INITIAL, 0.0, "N.s", "initial momentum"),
    FIXED("I1.zChassisInit", R_I1_ZCHASSIS_INIT, 1.0, "m", "initial height"),
    {"p.e", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_P_E, 0.0, NULL, -INFINITY, INFINITY, "N",
     "suspension force on the wheel", NO_STATE, NULL},
    {"p.f", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_P_F, 0.0, NULL, -INFINITY, INFINITY, "m/s",
     "wheel velocity", NO_STATE, NULL},
    {"zChassis", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_ZCHASSIS, 0.0, NULL, -INFINITY, INFINITY,
     "m", "chassis height (QSensor.q)", NO_STATE, NULL},
    STATE("C.zDelta", R_C_ZDELTA, "m", "suspension compression"),
    STATE("I1.moment", R_I1_MOMENT, "N.s", "chassis momentum"),
    STATE("I1.zChassis", R_I1_ZCHASSIS, "m", "chassis height (integrated in I1)"),
    STATE("QSensor.q", R_QSENSOR_Q, "m", "chassis height (integrated in QSensor, initially 1 m)"),
    RATE("C.p.f", R_C_P_F, VR_C_ZDELTA, "m/s", "compression rate p.f - v"),
    RATE("I1.p.e", R_I1_P_E, VR_I1_MOMENT, "N", "net force on the chassis"),
    RATE("I1.p.f", R_I1_P_F, VR_I1_ZCHASSIS, "m/s", "chassis velocity"),
    RATE("QSensor.p1.f", R_QSENSOR_P1_F, VR_QSENSOR_Q, "m/s", "chassis velocity"),
};

static const int STATE_SLOTS[] = {R_C_ZDELTA, R_I1_MOMENT, R_I1_ZCHASSIS, R_QSENSOR_Q};
static const int DERIVATIVE_SLOTS[] = {R_C_P_F, R_I1_P_E, R_I1_P_F, R_QSENSOR_P1_F};

static ModelStatus initialize(Instance *inst) {
    double *r = model_reals(inst);
    r[R_C_ZDELTA_INIT] = r[R_C_M] * G_N / r[R_C_K];
    r[R_C_ZDELTA] = r[R_C_ZDELTA_INIT];
    r[R_I1_MOMENT] = r[R_I1_MOMENT_INITIAL];
    r[R_I1_ZCHASSIS] = r[R_I1_ZCHASSIS_INIT];
    r[R_QSENSOR_Q] = 1.0; /* the original's QSensor.q_initial, not a variable of its description */
    return MODEL_OK;
}

/* The suspension force for the wheel velocity in the input slot and the state x. */
static double force(const double *r, const double *x) {
    return x[0] * r[R_C_K] + r[R_R_D] * (r[R_P_F] - x[1] / r[R_I1_M]);
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx) {
    (void)t;
    const double *r = model_reals(inst);
    double v = x[1] / r[R_I1_M];
    dx[0] = r[R_P_F] - v;
    dx[1] = force(r, x) - r[R_SE1_M] * G_N;
    dx[2] = v;
    dx[3] = v;
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    double *r = model_reals(inst);
    r[R_P_E] = force(r, x);
    r[R_ZCHASSIS] = x[3];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "qt_chassis",
    .guid = "{5b0d3c1e-7a84-4f2b-9c61-2e8f4d9a0b17}",
    .description = "Quarter truck chassis with the interface of ecos's 20-sim chassis.fmu",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_booleans = 0,
    .n_strings = 0,
    .default_step_size = 0.001,
    .n_states = 4,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = NULL,
    .outputs = outputs,
};
