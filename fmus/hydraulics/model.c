/* hydraulics: three hydraulic servo actuators (paper Sec. 4.1, Table 2).
 *
 * Each actuator is a critically centred 4-way spool valve feeding a double-acting,
 * equal-area cylinder.  States: the two chamber pressures of each cylinder (Pa).
 * "left" is the cap side: pressure there extends the piston, and a positive stroke
 * s (m, measured from the initial position) grows the left chamber:
 *
 *   V_left  = V0_left  + A s                 V_right = V0_right - A s      (m^3)
 *   force   = A (p_left - p_right)           (N, positive extends)
 *
 * Orifice law (flows in m^3/s into a chamber; x = spool displacement in m,
 * x+ = max(x, 0), x- = max(-x, 0)):
 *
 *   Q_left  = Kv [x+ g(p_s - p_left)  - x- g(p_left - p_t)]  - C_L (p_left - p_right)
 *   Q_right = Kv [x- g(p_s - p_right) - x+ g(p_right - p_t)] + C_L (p_left - p_right)
 *
 * with the regularised signed square root (dp in Pa, g in Pa^0.5)
 *
 *   g(dp) = dp / (dp^2 + dp_lin^2)^(1/4)
 *
 * which is sign(dp) sqrt(|dp|) within a relative (dp_lin/dp)^2/4 for |dp| >> dp_lin
 * and linear with the finite slope dp_lin^(-1/2) near dp = 0, so the Jacobian stays
 * finite.  Being signed, it also pushes a chamber back towards supply or tank when a
 * pressure overshoots them.  C_L (m^3/(s Pa)) is an optional leakage across the piston.
 *
 * Pressure build-up (linear bulk modulus beta, Pa):
 *
 *   dp_left/dt  = beta / V_left  (Q_left  - A ds/dt)
 *   dp_right/dt = beta / V_right (Q_right + A ds/dt)
 *
 * Clamp: a pressure at or above supply may not rise further, and one at or below tank
 * may not fall further (ideal relief and anti-cavitation valves): the derivative is
 * set to 0 there, and its Jacobian row too.  A fixed step may still overshoot a bound
 * by at most one step's change.
 *
 * Flow coefficient: the paper gives 1.49e-3 and 7.45e-4 "with spool displacement in
 * mm and pressure in kN/m^2".  We read the flow in litres per second (dm^3/s):
 * Q [l/s] = Kv_paper x [mm] sqrt(dp [kN/m^2]), i.e. Kv_SI = Kv_paper sqrt(1e-3)
 * in m^3/(s m Pa^0.5).  An unloaded piston (drop p_s/2 over each orifice) then moves
 * at 6.38e-3 m/s per mm of spool (actuator 1) and 3.99e-3 m/s per mm (actuators 2, 3;
 * tests/test_hydraulics.py::test_unloaded_piston_speed_per_mm_of_spool).
 * Reading the coefficient in plain SI instead gives 0.20 and 0.13 m/s per mm: the
 * paper's 3 s run with 1.2 / -0.9 / 1.2 mm spool steps would then drive the pistons
 * past their half strokes V0/A = 0.63 m and 0.21 m, so that reading cannot be meant.
 */
#include "model.h"

/* Value references: common (0, 1), globals (2..6), then 14 per actuator. */
enum { VR_P_SUPPLY = 2, VR_P_TANK, VR_BETA, VR_DP_LIN, VR_LEAKAGE, VR_ACTUATOR0 };
enum {
    A_AREA,
    A_VOLUME_LEFT,
    A_VOLUME_RIGHT,
    A_KV,
    A_SPOOL,
    A_STROKE,
    A_STROKE_RATE,
    A_P_LEFT,
    A_P_RIGHT,
    A_DER_P_LEFT,
    A_DER_P_RIGHT,
    A_FORCE,
    A_FLOW_LEFT,
    A_FLOW_RIGHT,
    A_COUNT
};
#define N_ACTUATORS 3
#define N_VARIABLES (VR_ACTUATOR0 + N_ACTUATORS * A_COUNT)
/* Every variable but `solver` is a real, stored in real slot (value reference - 1). */
#define SLOT(vr) ((vr) - 1)
#define ASLOT(k, field) SLOT(VR_ACTUATOR0 + (k) * A_COUNT + (field))
#define N_REALS SLOT(N_VARIABLES)

#define KV_SCALE 0.031622776601683794 /* sqrt(1e-3): paper's l/s, mm, kN/m^2 -> SI */

#define PARAM(name, field_vr, start, min, unit, desc)                                                    \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, SLOT(field_vr), start, NULL, min, INFINITY, unit, desc, \
     NO_STATE, NULL}

/* One actuator's table rows.  n: "1".."3"; base: its first value reference;
 * deps: its der() dependencies (spool, stroke, rate, pressures); pdeps: the force's. */
#define ACTUATOR(n, base, area, v0, kv, p_left0, p_right0, deps, pdeps)                                   \
    PARAM("area" n, (base) + A_AREA, area, 0, "m2", "piston area (both sides)"),                           \
    PARAM("volume_left" n, (base) + A_VOLUME_LEFT, v0, 0, "m3", "left (cap side) volume at stroke 0"),     \
    PARAM("volume_right" n, (base) + A_VOLUME_RIGHT, v0, 0, "m3", "right volume at stroke 0"),             \
    PARAM("Kv" n, (base) + A_KV, kv, 0, NULL,                                                              \
          "valve flow coefficient in m3/(s m Pa^0.5): Q = Kv x sqrt(dp) (paper value times sqrt(1e-3))"),  \
    {"spool" n, T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, SLOT((base) + A_SPOOL), 0.0, NULL, -INFINITY,    \
     INFINITY, "m", "spool displacement (positive: supply to left chamber)", NO_STATE, NULL},             \
    {"stroke" n, T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, SLOT((base) + A_STROKE), 0.0, NULL, -INFINITY,  \
     INFINITY, "m", "piston stroke from its initial position (positive extends)", NO_STATE, NULL},        \
    {"stroke_rate" n, T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, SLOT((base) + A_STROKE_RATE), 0.0, NULL,   \
     -INFINITY, INFINITY, "m/s", "piston velocity (positive extends)", NO_STATE, NULL},                    \
    {"p_left" n, T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, SLOT((base) + A_P_LEFT), p_left0, NULL,          \
     -INFINITY, INFINITY, "Pa", "left (cap side) chamber pressure", NO_STATE, ""},                         \
    {"p_right" n, T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, SLOT((base) + A_P_RIGHT), p_right0, NULL,       \
     -INFINITY, INFINITY, "Pa", "right chamber pressure", NO_STATE, ""},                                   \
    {"der(p_left" n ")", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, SLOT((base) + A_DER_P_LEFT), 0.0,    \
     NULL, -INFINITY, INFINITY, "Pa/s", "derivative of p_left" n, (base) + A_P_LEFT, deps},                \
    {"der(p_right" n ")", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, SLOT((base) + A_DER_P_RIGHT), 0.0,  \
     NULL, -INFINITY, INFINITY, "Pa/s", "derivative of p_right" n, (base) + A_P_RIGHT, deps},              \
    {"force" n, T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, SLOT((base) + A_FORCE), 0.0, NULL,           \
     -INFINITY, INFINITY, "N", "cylinder force A (p_left - p_right), positive extends", NO_STATE, pdeps},  \
    {"flow_left" n, T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, SLOT((base) + A_FLOW_LEFT), 0.0, NULL,    \
     -INFINITY, INFINITY, "m3/s", "valve and leakage flow into the left chamber", NO_STATE, NULL},        \
    {"flow_right" n, T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, SLOT((base) + A_FLOW_RIGHT), 0.0, NULL,  \
     -INFINITY, INFINITY, "m3/s", "valve and leakage flow into the right chamber", NO_STATE, NULL}

#define B1 (VR_ACTUATOR0)
#define B2 (VR_ACTUATOR0 + A_COUNT)
#define B3 (VR_ACTUATOR0 + 2 * A_COUNT)

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    PARAM("p_supply", VR_P_SUPPLY, 1.38e7, -INFINITY, "Pa", "supply pressure"),
    PARAM("p_tank", VR_P_TANK, 0.0, -INFINITY, "Pa", "tank (return) pressure"),
    PARAM("bulk_modulus", VR_BETA, 1.03e9, 0, "Pa", "effective bulk modulus of the oil"),
    PARAM("dp_lin", VR_DP_LIN, 1e5, 0, "Pa", "pressure drop below which the orifice law turns linear"),
    PARAM("leakage", VR_LEAKAGE, 0.0, 0, "m3/s.Pa", "leakage coefficient across each piston"),
    /* value references: actuator 1 at 7..20, 2 at 21..34, 3 at 35..48 */
    ACTUATOR("1", B1, 1.94e-2, 1.23e-2, 1.49e-3 * KV_SCALE, 8.14e6, 5.66e6, "11 12 13 14 15", "14 15"),
    ACTUATOR("2", B2, 1.55e-2, 3.28e-3, 7.45e-4 * KV_SCALE, 6.9e6, 6.9e6, "25 26 27 28 29", "28 29"),
    ACTUATOR("3", B3, 1.55e-2, 3.28e-3, 7.45e-4 * KV_SCALE, 6.9e6, 6.9e6, "39 40 41 42 43", "42 43"),
};

static const int STATE_SLOTS[] = {ASLOT(0, A_P_LEFT),  ASLOT(0, A_P_RIGHT), ASLOT(1, A_P_LEFT),
                                  ASLOT(1, A_P_RIGHT), ASLOT(2, A_P_LEFT),  ASLOT(2, A_P_RIGHT)};
static const int DERIVATIVE_SLOTS[] = {ASLOT(0, A_DER_P_LEFT),  ASLOT(0, A_DER_P_RIGHT),
                                       ASLOT(1, A_DER_P_LEFT),  ASLOT(1, A_DER_P_RIGHT),
                                       ASLOT(2, A_DER_P_LEFT),  ASLOT(2, A_DER_P_RIGHT)};

/* Regularised signed square root and its derivative (dp in Pa). */
static double g(double dp, double lin) { return dp / pow(dp * dp + lin * lin, 0.25); }

static double dg(double dp, double lin)
{
    const double s = dp * dp + lin * lin;
    return (0.5 * dp * dp + lin * lin) / pow(s, 1.25);
}

/* Chamber volumes of actuator k at its current stroke; error if one is not positive. */
static ModelStatus volumes(Instance *inst, int k, double *v_left, double *v_right)
{
    const double *r = model_reals(inst);
    const double a = r[ASLOT(k, A_AREA)], s = r[ASLOT(k, A_STROKE)];
    *v_left = r[ASLOT(k, A_VOLUME_LEFT)] + a * s;
    *v_right = r[ASLOT(k, A_VOLUME_RIGHT)] - a * s;
    if (*v_left <= 0 || *v_right <= 0) {
        model_log(inst, "logError",
                  "hydraulics: stroke%d = %g m leaves a chamber volume <= 0 (left %g m3, right %g m3)", k + 1, s,
                  *v_left, *v_right);
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

/* Flows into the two chambers of actuator k at pressures (pl, pr), m^3/s. */
static void flows(const double *r, int k, double pl, double pr, double *q_left, double *q_right)
{
    const double ps = r[SLOT(VR_P_SUPPLY)], pt = r[SLOT(VR_P_TANK)], lin = r[SLOT(VR_DP_LIN)];
    const double kv = r[ASLOT(k, A_KV)], x = r[ASLOT(k, A_SPOOL)];
    const double xp = x > 0 ? x : 0, xn = x < 0 ? -x : 0;
    const double leak = r[SLOT(VR_LEAKAGE)] * (pl - pr);
    *q_left = kv * (xp * g(ps - pl, lin) - xn * g(pl - pt, lin)) - leak;
    *q_right = kv * (xn * g(ps - pr, lin) - xp * g(pr - pt, lin)) + leak;
}

/* True if pressure p with rate dp is pushing out of [tank, supply]. */
static int clamped(const double *r, double p, double dp)
{
    return (p >= r[SLOT(VR_P_SUPPLY)] && dp > 0) || (p <= r[SLOT(VR_P_TANK)] && dp < 0);
}

/* Parameters the equations cannot live with. */
static ModelStatus initialize(Instance *inst)
{
    const double *r = model_reals(inst);
    if (!(r[SLOT(VR_P_SUPPLY)] > r[SLOT(VR_P_TANK)])) {
        model_log(inst, "logError", "hydraulics: p_supply = %g Pa must exceed p_tank = %g Pa", r[SLOT(VR_P_SUPPLY)],
                  r[SLOT(VR_P_TANK)]);
        return MODEL_ERROR;
    }
    if (!(r[SLOT(VR_DP_LIN)] > 0)) {
        model_log(inst, "logError", "hydraulics: dp_lin = %g Pa must be positive", r[SLOT(VR_DP_LIN)]);
        return MODEL_ERROR;
    }
    for (int k = 0; k < N_ACTUATORS; k++) {
        double vl, vr;
        if (volumes(inst, k, &vl, &vr) != MODEL_OK) return MODEL_ERROR;
    }
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    (void)t;
    double *r = model_reals(inst);
    for (int k = 0; k < N_ACTUATORS; k++) {
        double vl, vr, ql, qr;
        if (volumes(inst, k, &vl, &vr) != MODEL_OK) return MODEL_ERROR;
        const double pl = x[2 * k], pr = x[2 * k + 1];
        const double a_rate = r[ASLOT(k, A_AREA)] * r[ASLOT(k, A_STROKE_RATE)];
        const double beta = r[SLOT(VR_BETA)];
        flows(r, k, pl, pr, &ql, &qr);
        r[ASLOT(k, A_FLOW_LEFT)] = ql; /* locals: recorded flows, for volume balances */
        r[ASLOT(k, A_FLOW_RIGHT)] = qr;
        dx[2 * k] = beta / vl * (ql - a_rate);
        dx[2 * k + 1] = beta / vr * (qr + a_rate);
        if (clamped(r, pl, dx[2 * k])) dx[2 * k] = 0;
        if (clamped(r, pr, dx[2 * k + 1])) dx[2 * k + 1] = 0;
    }
    return MODEL_OK;
}

/* Block diagonal: each actuator's pressures depend only on each other. */
static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J)
{
    (void)t;
    const int n = 2 * N_ACTUATORS;
    const double *r = model_reals(inst);
    const double ps = r[SLOT(VR_P_SUPPLY)], pt = r[SLOT(VR_P_TANK)], lin = r[SLOT(VR_DP_LIN)];
    const double beta = r[SLOT(VR_BETA)], leak = r[SLOT(VR_LEAKAGE)];
    for (int i = 0; i < n * n; i++) J[i] = 0;
    for (int k = 0; k < N_ACTUATORS; k++) {
        double vl, vr, ql, qr;
        if (volumes(inst, k, &vl, &vr) != MODEL_OK) return MODEL_ERROR;
        const double pl = x[2 * k], pr = x[2 * k + 1];
        const double kv = r[ASLOT(k, A_KV)], xs = r[ASLOT(k, A_SPOOL)];
        const double xp = xs > 0 ? xs : 0, xn = xs < 0 ? -xs : 0;
        const double a_rate = r[ASLOT(k, A_AREA)] * r[ASLOT(k, A_STROKE_RATE)];
        const int il = 2 * k, ir = 2 * k + 1;
        flows(r, k, pl, pr, &ql, &qr);
        /* dQ_left/dp_left, dQ_right/dp_right; the cross terms are the leakage alone */
        const double dql = -kv * (xp * dg(ps - pl, lin) + xn * dg(pl - pt, lin)) - leak;
        const double dqr = -kv * (xn * dg(ps - pr, lin) + xp * dg(pr - pt, lin)) - leak;
        if (!clamped(r, pl, beta / vl * (ql - a_rate))) {
            J[il * n + il] = beta / vl * dql;
            J[il * n + ir] = beta / vl * leak;
        }
        if (!clamped(r, pr, beta / vr * (qr + a_rate))) {
            J[ir * n + il] = beta / vr * leak;
            J[ir * n + ir] = beta / vr * dqr;
        }
    }
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x)
{
    double *r = model_reals(inst);
    for (int k = 0; k < N_ACTUATORS; k++) {
        r[ASLOT(k, A_FORCE)] = r[ASLOT(k, A_AREA)] * (x[2 * k] - x[2 * k + 1]);
    }
    double dx[2 * N_ACTUATORS]; /* refreshes the recorded flows */
    return derivatives(inst, t, x, dx);
}

const ModelDef MODEL = {
    .identifier = "hydraulics",
    .guid = "{b7e3d1c2-5a49-4f0e-8d26-3c9a1e7f4b58}",
    .description = "Three spool-valve / double-acting cylinder hydraulic servos (chamber pressures as states)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_booleans = 0,
    .n_strings = 0,
    .n_states = 2 * N_ACTUATORS,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = outputs,
};
