/* qt_ground: the road of ecos's quarter truck (a 20-sim export, "ground"), with the original's
 * names for its parameters, input, outputs and state, and its equations:
 *
 *   zGround = Step.amplitude (t >= Step.start_time)   road height, a step
 *   p.f = w (zGround - u0) + Derivative.rate_int      road velocity: zGround differentiated with
 *   Derivative.rate_int' = -w p.f                     bandwidth w = 2 pi Derivative.fh
 *
 * u0 is zGround at initialization and Derivative.rate_int starts at Derivative.initial, so p.f
 * starts at Derivative.initial and integrates to the step's height.  The input p.e (the tyre
 * force) is not used; the description declares no dependencies, like the original's.  Time is
 * the master's: the original counts its own time from 0 whatever the start time, which makes no
 * difference where the step lies before the start (ecos's scene starts at 10 s: the road has
 * stepped, p.f is 0 in both, 7e-15 m/s in the original) or the start is 0. */
#include "model.h"

#define PI 3.14159265358979 /* 20-sim's pi */

enum {
    VR_SOLVER,
    VR_INTERNAL_STEP,
    VR_FH,
    VR_AMPLITUDE,
    VR_START_TIME,
    VR_INITIAL,
    VR_P_E,
    VR_P_F,
    VR_ZGROUND,
    VR_RATE_INT,
    VR_INPUT_INITIAL,
    VR_DER_RATE_INT,
    N_VARIABLES
};
enum {
    R_FH = R_MODEL_START,
    R_AMPLITUDE,
    R_START_TIME,
    R_INITIAL,
    R_P_E,
    R_P_F,
    R_ZGROUND,
    R_RATE_INT,
    R_INPUT_INITIAL,
    R_DER_RATE_INT,
    N_REALS
};

#define TUNABLE(name, slot, start, unit, description) \
    {name, T_REAL, C_PARAMETER, V_TUNABLE, I_EXACT, slot, start, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    TUNABLE("Derivative.fh", R_FH, 10.0, "Hz", "Differentiation bandwidth [Hz]"),
    TUNABLE("Step.amplitude", R_AMPLITUDE, 0.1, "m", "height of the step"),
    TUNABLE("Step.start_time", R_START_TIME, 1.0, "s", "time of the step"),
    {"Derivative.initial", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_INITIAL, 0.0, NULL, -INFINITY, INFINITY,
     "m/s", "Initial output", NO_STATE, NULL},
    {"p.e", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_P_E, 0.0, NULL, -INFINITY, INFINITY, "N",
     "tyre force (not used)", NO_STATE, NULL},
    {"p.f", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_P_F, 0.0, NULL, -INFINITY, INFINITY, "m/s",
     "road velocity", NO_STATE, NULL},
    {"zGround", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_ZGROUND, 0.0, NULL, -INFINITY, INFINITY, "m",
     "road height", NO_STATE, NULL},
    {"Derivative.rate_int", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_RATE_INT, 0.0, NULL, -INFINITY,
     INFINITY, "m/s", "state of the differentiator", NO_STATE, NULL},
    {"Derivative.input_initial", T_REAL, C_LOCAL, V_FIXED, I_CALCULATED, R_INPUT_INITIAL, 0.0, NULL, -INFINITY,
     INFINITY, "m", "zGround at initialization", NO_STATE, NULL},
    {"der(Derivative.rate_int)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_RATE_INT, 0.0, NULL,
     -INFINITY, INFINITY, "m/s2", "-w p.f", VR_RATE_INT, NULL},
};

static const int STATE_SLOTS[] = {R_RATE_INT};
static const int DERIVATIVE_SLOTS[] = {R_DER_RATE_INT};

static double height(const double *r, double t) { return t < r[R_START_TIME] ? 0.0 : r[R_AMPLITUDE]; }

static double velocity(const double *r, double t, const double *x) {
    return 2.0 * PI * r[R_FH] * (height(r, t) - r[R_INPUT_INITIAL]) + x[0];
}

static ModelStatus initialize(Instance *inst) {
    double *r = model_reals(inst);
    r[R_INPUT_INITIAL] = height(r, model_time(inst));
    r[R_RATE_INT] = r[R_INITIAL];
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx) {
    const double *r = model_reals(inst);
    dx[0] = -2.0 * PI * r[R_FH] * velocity(r, t, x);
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    double *r = model_reals(inst);
    r[R_ZGROUND] = height(r, t);
    r[R_P_F] = velocity(r, t, x);
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "qt_ground",
    .guid = "{d3f86b20-1e4c-4a97-8b05-7c2a9e61f4d8}",
    .description = "Quarter truck road with the interface of ecos's 20-sim ground.fmu",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_booleans = 0,
    .n_strings = 0,
    .default_step_size = 0.001,
    .n_states = 1,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = NULL,
    .outputs = outputs,
};
