/* ecs_sw: the cooling-pack controller of OMSimulator's embrace scene (a Simulink model, "OpenSW"),
 * with its interface: inputs Input.TLiquid (Real) and Input.Aircraft_State (the original's
 * Enumeration Aircraft_State_Type, 0 Stationary .. 4 Airborne: an Integer here), output TCoolingPack.
 *
 * A discrete PI controller with anti-windup sampled every Ts = 1/30 s: e = 293 - TLiquid,
 * v = Kp e + I + Ki (e + W) Ts, s = v saturated to [-200, 200]; the integrator I and the windup
 * memory W are unit delays, I <- I + Ki (e + W) Ts and W <- s - v; the output, s + 293 when
 * airborne, else 313, is computed in the sample as well, so after a step it is that of the last
 * sample and a later input changes it at the next one.  Here I, W and the output are states stepped
 * by Euler with the internal step Ts (the default), which gives those updates: one sample every Ts
 * of time (the original takes one sample per doStep whatever its length: the same where the master
 * steps by Ts). */
#include "model.h"

#define TS (1.0 / 30.0)
#define KP 5.0
#define KI 1.0
#define T_SET 293.0
#define T_GROUND 313.0
#define LIMIT 200.0
#define AIRBORNE 4

enum {
    VR_SOLVER,
    VR_INTERNAL_STEP,
    VR_TLIQUID,
    VR_STATE,
    VR_TCOOLING,
    VR_I,
    VR_W,
    VR_DER_I,
    VR_DER_W,
    VR_DER_TCOOLING,
    N_VARIABLES
};
enum { R_TLIQUID = R_MODEL_START, R_TCOOLING, R_I, R_W, R_DER_I, R_DER_W, R_DER_TCOOLING, N_REALS };
enum { I_STATE = I_MODEL_START, N_INTEGERS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, TS),
    {"Input.TLiquid", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_TLIQUID, 0.0, NULL, -INFINITY, INFINITY,
     NULL, "liquid temperature", NO_STATE, NULL},
    {"Input.Aircraft_State", T_INTEGER, C_INPUT, V_DISCRETE, I_DEFAULT, I_STATE, 0.0, NULL, -INFINITY,
     INFINITY, NULL, "0 stationary, 1 rolling, 2 rotating, 3 touching down, 4 airborne", NO_STATE, NULL},
    {"TCoolingPack", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_TCOOLING, 0.0, NULL, -INFINITY, INFINITY,
     NULL, "cooling pack temperature", NO_STATE, "4"},
    {"UnitDelay", T_REAL, C_LOCAL, V_CONTINUOUS, I_EXACT, R_I, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "integrator I of the PI controller", NO_STATE, NULL},
    {"UnitDelay1", T_REAL, C_LOCAL, V_CONTINUOUS, I_EXACT, R_W, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "anti-windup memory W", NO_STATE, NULL},
    {"der(UnitDelay)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_I, 0.0, NULL, -INFINITY,
     INFINITY, NULL, "Ki (e + W)", VR_I, "2 6"},
    {"der(UnitDelay1)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_W, 0.0, NULL, -INFINITY,
     INFINITY, NULL, "(s - v - W) / Ts", VR_W, "2 5 6"},
    {"der(TCoolingPack)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_TCOOLING, 0.0, NULL, -INFINITY,
     INFINITY, NULL, "(the sample's output - TCoolingPack) / Ts", VR_TCOOLING, "2 3 4 5 6"},
};

static const int STATE_SLOTS[] = {R_I, R_W, R_TCOOLING};
static const int DERIVATIVE_SLOTS[] = {R_DER_I, R_DER_W, R_DER_TCOOLING};

/* The controller before (v) and after (s) saturation, for the temperature and states given. */
static void control(double t_liquid, const double *x, double *v, double *s) {
    double e = T_SET - t_liquid;
    *v = KP * e + (x[0] + KI * (e + x[1]) * TS);
    *s = fmin(LIMIT, fmax(*v, -LIMIT));
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx) {
    (void)t;
    double u = model_reals(inst)[R_TLIQUID], v, s;
    control(u, x, &v, &s);
    double y = model_integers(inst)[I_STATE] == AIRBORNE ? s + T_SET : T_GROUND;
    dx[0] = KI * ((T_SET - u) + x[1]);
    dx[1] = ((s - v) - x[1]) / TS;
    dx[2] = (y - x[2]) / TS;
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "ecs_sw",
    .guid = "{3f9d2b6e-81c4-4a07-b5e3-6d0a9c1f7e42}",
    .description = "cooling-pack controller of the embrace scene (OpenSW): a discrete PI with anti-windup",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .n_states = 3,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .derivatives = derivatives,
    .default_step_size = TS,
};
