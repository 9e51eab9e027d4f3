/* dcmotor: three armature-controlled DC motors with state feedback (paper Sec. 4.2, Table 3).
 *
 * Motor k drives joint k of the arm (joints between bodies 1-2, 2-3, 3-4).  States: the
 * armature currents i_k (A).  Inputs: joint angles q_k (rad) and rates qd_k (rad/s) of
 * the mechanism, and an extra voltage w_ext_k (V, 0 in closed loop).
 *
 *   L di_k/dt = w_k - R i_k - Ke qd_k               (eq. 11, Kirchhoff's voltage law)
 *   torque_k  = Kt_k i_k                            (N m, to the mechanism)
 *   w_k       = R i_ref_k - sum_j K_k_j (z_j - z*_j) + w_ext_k          (eq. 13)
 *
 * z = (q1..q3, qd1..qd3, i1..i3) and z* = (q_ref, 0, i_ref).  i_ref_k is the holding
 * current that balances gravity at the set point, and R i_ref_k the voltage that keeps
 * it flowing, so that z* is an exact equilibrium of the closed loop.  The gains K
 * and holding currents come from models/dc-motor-arm/place_poles.py (pole placement on
 * the linearised coupled model).  If w_max > 0 each w_k is clamped to [-w_max, w_max].
 * Ke and Kt are printed independently in the paper (gearing included); we keep both.
 */
#include "model.h"

enum {
    VR_R = 2,
    VR_L,
    VR_KE,
    VR_KT1,
    VR_W_MAX = VR_KT1 + 3,
    VR_Q_REF1,
    VR_I_REF1 = VR_Q_REF1 + 3,
    VR_K11 = VR_I_REF1 + 3, /* K_1_1 .. K_3_9, row major */
    VR_Q1 = VR_K11 + 27,
    VR_QD1 = VR_Q1 + 3,
    VR_W_EXT1 = VR_QD1 + 3,
    VR_I1 = VR_W_EXT1 + 3,
    VR_DER_I1 = VR_I1 + 3,
    VR_TORQUE1 = VR_DER_I1 + 3,
    VR_W1 = VR_TORQUE1 + 3,
    N_VARIABLES = VR_W1 + 3
};
/* Every variable but `solver` is a real, stored in real slot (value reference - 1). */
#define SLOT(vr) ((vr) - 1)
#define N_REALS SLOT(N_VARIABLES)
#define N_MOTORS 3
#define N_Z 9

#define PARAM(name, vr, start, min, unit, desc)                                                          \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, SLOT(vr), start, NULL, min, INFINITY, unit, desc,      \
     NO_STATE, NULL}
#define INPUT(name, vr, unit, desc)                                                                      \
    {name, T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, SLOT(vr), 0.0, NULL, -INFINITY, INFINITY, unit,     \
     desc, NO_STATE, NULL}
#define GAIN(row, col)                                                                                   \
    {"K_" #row "_" #col, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, SLOT(VR_K11 + 9 * (row - 1) + col - 1), \
     0.0, NULL, -INFINITY, INFINITY, NULL,                                                               \
     "feedback gain of motor " #row " on z" #col " (z = q1..q3 rad, qd1..qd3 rad/s, i1..i3 A; V per unit)", \
     NO_STATE, NULL}
#define GAIN_ROW(row)                                                                                    \
    GAIN(row, 1), GAIN(row, 2), GAIN(row, 3), GAIN(row, 4), GAIN(row, 5), GAIN(row, 6), GAIN(row, 7),    \
        GAIN(row, 8), GAIN(row, 9)
#define DEG (3.14159265358979323846 / 180.0)

/* Value references of the inputs and states, for the dependency lists. */
#define ALL_DEPS "42 43 44 45 46 47 48 49 50 51 52 53"

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_SEMI_IMPLICIT_EULER, 0.0),
    PARAM("R", VR_R, 5.0, 0, "Ohm", "armature resistance"),
    PARAM("L", VR_L, 0.02, 0, "H", "armature inductance"),
    PARAM("Ke", VR_KE, 0.5, 0, "V.s/rad", "back-emf gain"),
    PARAM("Kt1", VR_KT1, 20.0, 0, "N.m/A", "torque gain of motor 1"),
    PARAM("Kt2", VR_KT1 + 1, 15.0, 0, "N.m/A", "torque gain of motor 2"),
    PARAM("Kt3", VR_KT1 + 2, 10.0, 0, "N.m/A", "torque gain of motor 3"),
    PARAM("w_max", VR_W_MAX, 0.0, 0, "V", "voltage limit |w_k| <= w_max; 0: none"),
    PARAM("q1_ref", VR_Q_REF1, 0.0, -INFINITY, "rad", "set point of joint 1"),
    PARAM("q2_ref", VR_Q_REF1 + 1, 45.0 * DEG, -INFINITY, "rad", "set point of joint 2"),
    PARAM("q3_ref", VR_Q_REF1 + 2, 300.0 * DEG, -INFINITY, "rad", "set point of joint 3"),
    PARAM("i_ref1", VR_I_REF1, 0.0, -INFINITY, "A", "holding current of motor 1 at the set point"),
    PARAM("i_ref2", VR_I_REF1 + 1, 0.0, -INFINITY, "A", "holding current of motor 2 at the set point"),
    PARAM("i_ref3", VR_I_REF1 + 2, 0.0, -INFINITY, "A", "holding current of motor 3 at the set point"),
    GAIN_ROW(1),
    GAIN_ROW(2),
    GAIN_ROW(3),
    INPUT("q1", VR_Q1, "rad", "angle of joint 1"),
    INPUT("q2", VR_Q1 + 1, "rad", "angle of joint 2"),
    INPUT("q3", VR_Q1 + 2, "rad", "angle of joint 3"),
    INPUT("qd1", VR_QD1, "rad/s", "rate of joint 1"),
    INPUT("qd2", VR_QD1 + 1, "rad/s", "rate of joint 2"),
    INPUT("qd3", VR_QD1 + 2, "rad/s", "rate of joint 3"),
    INPUT("w_ext1", VR_W_EXT1, "V", "voltage added to the control law of motor 1"),
    INPUT("w_ext2", VR_W_EXT1 + 1, "V", "voltage added to the control law of motor 2"),
    INPUT("w_ext3", VR_W_EXT1 + 2, "V", "voltage added to the control law of motor 3"),
    {"i1", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, SLOT(VR_I1), 0.0, NULL, -INFINITY, INFINITY, "A",
     "armature current of motor 1", NO_STATE, ""},
    {"i2", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, SLOT(VR_I1 + 1), 0.0, NULL, -INFINITY, INFINITY, "A",
     "armature current of motor 2", NO_STATE, ""},
    {"i3", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, SLOT(VR_I1 + 2), 0.0, NULL, -INFINITY, INFINITY, "A",
     "armature current of motor 3", NO_STATE, ""},
    {"der(i1)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, SLOT(VR_DER_I1), 0.0, NULL, -INFINITY, INFINITY,
     "A/s", "derivative of i1", VR_I1, ALL_DEPS},
    {"der(i2)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, SLOT(VR_DER_I1 + 1), 0.0, NULL, -INFINITY,
     INFINITY, "A/s", "derivative of i2", VR_I1 + 1, ALL_DEPS},
    {"der(i3)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, SLOT(VR_DER_I1 + 2), 0.0, NULL, -INFINITY,
     INFINITY, "A/s", "derivative of i3", VR_I1 + 2, ALL_DEPS},
    {"torque1", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, SLOT(VR_TORQUE1), 0.0, NULL, -INFINITY,
     INFINITY, "N.m", "motor torque on joint 1", NO_STATE, "51"},
    {"torque2", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, SLOT(VR_TORQUE1 + 1), 0.0, NULL, -INFINITY,
     INFINITY, "N.m", "motor torque on joint 2", NO_STATE, "52"},
    {"torque3", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, SLOT(VR_TORQUE1 + 2), 0.0, NULL, -INFINITY,
     INFINITY, "N.m", "motor torque on joint 3", NO_STATE, "53"},
    {"w1", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, SLOT(VR_W1), 0.0, NULL, -INFINITY, INFINITY, "V",
     "armature voltage of motor 1", NO_STATE, ALL_DEPS},
    {"w2", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, SLOT(VR_W1 + 1), 0.0, NULL, -INFINITY, INFINITY, "V",
     "armature voltage of motor 2", NO_STATE, ALL_DEPS},
    {"w3", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, SLOT(VR_W1 + 2), 0.0, NULL, -INFINITY, INFINITY, "V",
     "armature voltage of motor 3", NO_STATE, ALL_DEPS},
};

static const int STATE_SLOTS[] = {SLOT(VR_I1), SLOT(VR_I1 + 1), SLOT(VR_I1 + 2)};
static const int DERIVATIVE_SLOTS[] = {SLOT(VR_DER_I1), SLOT(VR_DER_I1 + 1), SLOT(VR_DER_I1 + 2)};

/* Control voltage of motor k at currents i (eq. 13); *saturated: the limit is active. */
static double voltage(const double *r, int k, const double *i, int *saturated)
{
    const double *gain = &r[SLOT(VR_K11 + N_Z * k)];
    double w = r[SLOT(VR_R)] * r[SLOT(VR_I_REF1 + k)] + r[SLOT(VR_W_EXT1 + k)];
    for (int j = 0; j < N_MOTORS; j++) {
        w -= gain[j] * (r[SLOT(VR_Q1 + j)] - r[SLOT(VR_Q_REF1 + j)]);
        w -= gain[3 + j] * r[SLOT(VR_QD1 + j)];
        w -= gain[6 + j] * (i[j] - r[SLOT(VR_I_REF1 + j)]);
    }
    const double w_max = r[SLOT(VR_W_MAX)];
    *saturated = w_max > 0 && (w > w_max || w < -w_max);
    if (*saturated) w = w > 0 ? w_max : -w_max;
    return w;
}

static ModelStatus initialize(Instance *inst)
{
    if (!(model_reals(inst)[SLOT(VR_L)] > 0)) {
        model_log(inst, "logError", "dcmotor: inductance L = %g H must be positive", model_reals(inst)[SLOT(VR_L)]);
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    (void)t;
    const double *r = model_reals(inst);
    for (int k = 0; k < N_MOTORS; k++) {
        int saturated;
        const double w = voltage(r, k, x, &saturated);
        dx[k] = (w - r[SLOT(VR_R)] * x[k] - r[SLOT(VR_KE)] * r[SLOT(VR_QD1 + k)]) / r[SLOT(VR_L)];
    }
    return MODEL_OK;
}

static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J)
{
    (void)t;
    const double *r = model_reals(inst);
    const double l = r[SLOT(VR_L)];
    for (int k = 0; k < N_MOTORS; k++) {
        int saturated;
        (void)voltage(r, k, x, &saturated);
        for (int j = 0; j < N_MOTORS; j++) {
            const double dw = saturated ? 0.0 : -r[SLOT(VR_K11 + N_Z * k + 6 + j)];
            J[k * N_MOTORS + j] = (dw - (k == j ? r[SLOT(VR_R)] : 0.0)) / l;
        }
    }
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x)
{
    (void)t;
    double *r = model_reals(inst);
    for (int k = 0; k < N_MOTORS; k++) {
        int saturated;
        r[SLOT(VR_TORQUE1 + k)] = r[SLOT(VR_KT1 + k)] * x[k];
        r[SLOT(VR_W1 + k)] = voltage(r, k, x, &saturated);
    }
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "dcmotor",
    .guid = "{2d8f6a91-3c47-4b5e-a0d2-7e1b9c4f6a35}",
    .description = "Three DC motor armature circuits with the state-feedback law w = -K (z - z*) (eq. 13)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .n_booleans = 0,
    .n_strings = 0,
    .n_states = N_MOTORS,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = outputs,
};
