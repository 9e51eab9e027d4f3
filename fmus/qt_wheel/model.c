/* qt_wheel: the wheel of ecos's quarter truck (a 20-sim bond-graph export, "wheel"), with the
 * original's names for its parameters, inputs, outputs and states, and its equations:
 *
 *   v = I.moment / I.mWheel                           wheel velocity, the output p1.f
 *   p.e = C.kWheel C.zDelta + R.dWheel (p.f - v)      tyre force on the ground; p.f: ground velocity
 *   C.zDelta' = p.f - v                               tyre compression
 *   I.moment' = p.e - Se.mWheel g - p1.e              momentum: tyre force, weight, suspension force p1.e
 *   I.zWheel' = QSensor1.q' = v                       height (QSensor1.q is the output zWheel)
 *
 * starting from static equilibrium under wheel and chassis: C.zDelta = (C.mChassis + C.mWheel) g /
 * C.kWheel (computed at initialization as the original does), at rest, at height 0.5 m.  p.e
 * depends directly on the input p.f (through R.dWheel); like the original's the description
 * declares no dependencies.  RK4, one step per communication step (the original: steps of at
 * most 1 ms). */
#include "model.h"

#define G_N 9.80665 /* m/s2, 20-sim's g_n */

enum {
    VR_SOLVER,
    VR_INTERNAL_STEP,
    VR_C_MWHEEL,
    VR_C_MCHASSIS,
    VR_C_K,
    VR_I_M,
    VR_R_D,
    VR_SE_M,
    VR_C_ZDELTA_INIT,
    VR_I_MOMENT_INITIAL,
    VR_I_ZWHEEL_INIT,
    VR_P_E,
    VR_P_F,
    VR_P1_E,
    VR_P1_F,
    VR_ZWHEEL,
    VR_C_ZDELTA,
    VR_I_MOMENT,
    VR_I_ZWHEEL,
    VR_QSENSOR1_Q,
    VR_C_P_F,
    VR_I_P_E,
    VR_I_P_F,
    VR_QSENSOR1_P1_F,
    N_VARIABLES
};
enum {
    R_C_MWHEEL = R_MODEL_START,
    R_C_MCHASSIS,
    R_C_K,
    R_I_M,
    R_R_D,
    R_SE_M,
    R_C_ZDELTA_INIT,
    R_I_MOMENT_INITIAL,
    R_I_ZWHEEL_INIT,
    R_P_E,
    R_P_F,
    R_P1_E,
    R_P1_F,
    R_ZWHEEL,
    R_C_ZDELTA,
    R_I_MOMENT,
    R_I_ZWHEEL,
    R_QSENSOR1_Q,
    R_C_P_F,
    R_I_P_E,
    R_I_P_F,
    R_QSENSOR1_P1_F,
    N_REALS
};

#define TUNABLE(name, slot, start, unit, description) \
    {name, T_REAL, C_PARAMETER, V_TUNABLE, I_EXACT, slot, start, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define FIXED(name, slot, start, unit, description) \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, slot, start, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define INPUT(name, slot, unit, description) \
    {name, T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define OUTPUT(name, slot, unit, description) \
    {name, T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define STATE(name, slot, unit, description) \
    {name, T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define RATE(name, slot, state, unit, description) \
    {name, T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, state, NULL}

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    TUNABLE("C.mWheel", R_C_MWHEEL, 40.0, "kg", "wheel mass in the initial tyre compression"),
    TUNABLE("C.mChassis", R_C_MCHASSIS, 400.0, "kg", "chassis mass in the initial tyre compression"),
    TUNABLE("C.kWheel", R_C_K, 150000.0, "N/m", "tyre stiffness"),
    TUNABLE("I.mWheel", R_I_M, 40.0, "kg", "wheel mass (inertia)"),
    TUNABLE("R.dWheel", R_R_D, 0.0, "N.s/m", "tyre damping"),
    TUNABLE("Se.mWheel", R_SE_M, 40.0, "kg", "wheel mass (weight)"),
    FIXED("C.zDeltaInit", R_C_ZDELTA_INIT, 0.0287661733333333, "m",
          "initial compression: computed at initialization as (C.mChassis + C.mWheel) g / C.kWheel"),
    FIXED("I.moment_initial", R_I_MOMENT_INITIAL, 0.0, "N.s", "initial momentum"),
    FIXED("I.zWheelInit", R_I_ZWHEEL_INIT, 0.5, "m", "initial height"),
    OUTPUT("p.e", R_P_E, "N", "tyre force on the ground"),
    INPUT("p.f", R_P_F, "m/s", "ground velocity"),
    INPUT("p1.e", R_P1_E, "N", "suspension force from the chassis"),
    OUTPUT("p1.f", R_P1_F, "m/s", "wheel velocity"),
    OUTPUT("zWheel", R_ZWHEEL, "m", "wheel height (QSensor1.q)"),
    STATE("C.zDelta", R_C_ZDELTA, "m", "tyre compression"),
    STATE("I.moment", R_I_MOMENT, "N.s", "wheel momentum"),
    STATE("I.zWheel", R_I_ZWHEEL, "m", "wheel height (integrated in I)"),
    STATE("QSensor1.q", R_QSENSOR1_Q, "m", "wheel height (integrated in QSensor1, initially 0.5 m)"),
    RATE("C.p.f", R_C_P_F, VR_C_ZDELTA, "m/s", "compression rate p.f - v"),
    RATE("I.p.e", R_I_P_E, VR_I_MOMENT, "N", "net force on the wheel"),
    RATE("I.p.f", R_I_P_F, VR_I_ZWHEEL, "m/s", "wheel velocity"),
    RATE("QSensor1.p1.f", R_QSENSOR1_P1_F, VR_QSENSOR1_Q, "m/s", "wheel velocity"),
};

static const int STATE_SLOTS[] = {R_C_ZDELTA, R_I_MOMENT, R_I_ZWHEEL, R_QSENSOR1_Q};
static const int DERIVATIVE_SLOTS[] = {R_C_P_F, R_I_P_E, R_I_P_F, R_QSENSOR1_P1_F};

static ModelStatus initialize(Instance *inst) {
    double *r = model_reals(inst);
    r[R_C_ZDELTA_INIT] = (r[R_C_MCHASSIS] + r[R_C_MWHEEL]) * G_N / r[R_C_K];
    r[R_C_ZDELTA] = r[R_C_ZDELTA_INIT];
    r[R_I_MOMENT] = r[R_I_MOMENT_INITIAL];
    r[R_I_ZWHEEL] = r[R_I_ZWHEEL_INIT];
    r[R_QSENSOR1_Q] = 0.5; /* the original's QSensor1.q_initial, not a variable of its description */
    return MODEL_OK;
}

/* The tyre force for the ground velocity in the input slot and the state x. */
static double tyre(const double *r, const double *x) {
    return x[0] * r[R_C_K] + r[R_R_D] * (r[R_P_F] - x[1] / r[R_I_M]);
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx) {
    (void)t;
    const double *r = model_reals(inst);
    double v = x[1] / r[R_I_M];
    dx[0] = r[R_P_F] - v;
    dx[1] = (tyre(r, x) - r[R_SE_M] * G_N) - r[R_P1_E];
    dx[2] = v;
    dx[3] = v;
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    double *r = model_reals(inst);
    r[R_P_E] = tyre(r, x);
    r[R_P1_F] = x[1] / r[R_I_M];
    r[R_ZWHEEL] = x[3];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "qt_wheel",
    .guid = "{9e4a1f62-3c57-4d08-b2a9-6f1e0c8d7b35}",
    .description = "Quarter truck wheel with the interface of ecos's 20-sim wheel.fmu",
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
