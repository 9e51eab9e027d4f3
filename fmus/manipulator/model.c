/* manipulator: six-body arm with one closed loop (paper Sec. 2, 4.1, 4.2; Tables 2, 3).
 *
 * Bodies 1 (ground) .. 6 in relative joint coordinates q1..q6:
 *   q1  revolute 1-2 about the global z axis through the origin (base turns)
 *   q2  revolute 2-3 about body 2's x axis at point j2 of body 2 (shoulder)
 *   q3  revolute 3-4 about body 3's x axis at point j3 of body 3 (elbow)
 *   q4  revolute 4-5 about body 4's x axis at point j4 of body 4 (strut hinge B)
 *   q5, q6  cylindrical joint 5-6 along body 5's y axis: q5 = distance from B to the
 *       origin of body 6 (m), q6 = turn of body 6 about that axis (rad)
 * The loop 3-4-5-6 closes with a revolute joint 6-3 at point A = a3 of body 3, axis x:
 *   Phi1 = (p6 - A) . y3,  Phi2 = (p6 - A) . z3,  Phi3 = x6 . (x3 x y5)
 * (the out-of-plane components hold identically since all x axes stay parallel).
 * Independent coordinates v = (q1, q2, q3), dependent u = (q4, q5, q6).
 *
 * Method (the paper's): at every evaluation u is found by Newton from the last
 * solution, R1 = -Phi_u^-1 Phi_v (eq. 6), R2 = -Phi_u^-1 gamma (eq. 7, gamma = the
 * velocity-product part of d2Phi/dt2), and M_bar v'' = Q_bar (eqs. 8-10) is solved by
 * Cholesky.  M and Q come from body Jacobians: M = sum J^T diag(m, I) J,
 * Q = sum J^T (applied - velocity-product inertia forces).
 * States (v, v'); body data (cg, principal inertias along the global axes) are given
 * in the "table" pose q*_table; geometry is in local (y, z) coordinates of each body.
 * Efforts: joint torques on q1..q3 (actuation 0) or forces of three cylinders between
 * attachment points (actuation 1, points given globally in the table pose).
 */
#include <string.h>

#include "model.h"

#define NB 5 /* moving bodies 2..6 */
#define NQ 6
#define NCYL 3
#define PI 3.14159265358979323846
#define DEG (PI / 180.0)
#define NEWTON_TOL 1e-12   /* |Phi| (m, and 1 for Phi3) */
#define NEWTON_MAX_IT 30
#define COND_MAX 1e8       /* Frobenius condition number of Phi_u beyond which the loop is singular */

/* Integer variables first (slots 1..7), then reals (slot = vr - VR_R0 + 1). */
enum { VR_ACTUATION = 2, VR_CYL_BODY0 = 3, VR_R0 = VR_CYL_BODY0 + 2 * NCYL };
enum { I_ACTUATION = I_MODEL_START, I_CYL_BODY0, N_INTEGERS = I_CYL_BODY0 + 2 * NCYL };
enum { B_M, B_IXX, B_IYY, B_IZZ, B_CGX, B_CGY, B_CGZ, B_COUNT };
enum { C_AX, C_AY, C_AZ, C_BX, C_BY, C_BZ, C_COUNT };
enum {
    VR_V1 = VR_R0, /* states v1..v3, vd1..vd3 */
    VR_DER = VR_V1 + 6,
    VR_G = VR_DER + 6,
    VR_DAMP1,
    VR_BODY0 = VR_DAMP1 + 3,
    VR_J2Y = VR_BODY0 + NB * B_COUNT,
    VR_J2Z,
    VR_J3Y,
    VR_J3Z,
    VR_J4Y,
    VR_J4Z,
    VR_A3Y,
    VR_A3Z,
    VR_QTAB1,
    VR_Q0_1 = VR_QTAB1 + 3,
    VR_QD0_1 = VR_Q0_1 + 3,
    VR_CYL0 = VR_QD0_1 + 3,
    VR_EFFORT1 = VR_CYL0 + NCYL * C_COUNT,
    VR_DIST1 = VR_EFFORT1 + 3,
    VR_STROKE1 = VR_DIST1 + 3,
    VR_RATE1 = VR_STROKE1 + 3,
    VR_Q1 = VR_RATE1 + 3,
    VR_QD1 = VR_Q1 + 6,
    VR_B6P = VR_QD1 + 6,
    VR_B6V = VR_B6P + 3,
    VR_B6A = VR_B6V + 3,
    VR_ENERGY = VR_B6A + 3,
    VR_RESIDUAL,
    VR_MBAR_MIN,
    VR_MBAR = VR_MBAR_MIN + 1,
    VR_NEWTON_IT = VR_MBAR + 9,
    VR_U = VR_NEWTON_IT + 1, /* Newton warm start q4..q6 */
    VR_LEN0 = VR_U + 3,
    N_VARIABLES = VR_LEN0 + 3
};
#define RS(vr) ((vr) - VR_R0 + R_MODEL_START)
/* Derived body data, written by initialize (not variables, but part of the FMU state). */
enum {
    H_S = RS(N_VARIABLES),    /* local cg of each body, NB x 3 */
    H_I = H_S + NB * 3,       /* local inertia tensor about the cg, NB x 9 */
    H_CP = H_I + NB * 9,      /* local cylinder attachment points, NCYL x 6 */
    N_REALS = H_CP + NCYL * 6
};

#define PARAM(name, vr, start, min, unit, desc)                                                          \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, RS(vr), start, NULL, min, INFINITY, unit, desc,        \
     NO_STATE, NULL}
#define IPARAM(name, vr, start, min, max, desc)                                                          \
    {name, T_INTEGER, C_PARAMETER, V_FIXED, I_EXACT, (vr) - VR_ACTUATION + I_ACTUATION, start, NULL, min, \
     max, NULL, desc, NO_STATE, NULL}
#define INPUT(name, vr, unit, desc)                                                                      \
    {name, T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, RS(vr), 0.0, NULL, -INFINITY, INFINITY, unit, desc, \
     NO_STATE, NULL}
#define OUTPUT(name, vr, unit, desc)                                                                     \
    {name, T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, RS(vr), 0.0, NULL, -INFINITY, INFINITY, unit,   \
     desc, NO_STATE, "states"} /* a function of the state: it does not change when inputs do */
#define FORCED(name, vr, unit, desc)                                                                     \
    {name, T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, RS(vr), 0.0, NULL, -INFINITY, INFINITY, unit,   \
     desc, NO_STATE, NULL} /* depends on the forces or torques as well (an acceleration) */
#define LOCAL(name, vr, unit, desc)                                                                      \
    {name, T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, RS(vr), 0.0, NULL, -INFINITY, INFINITY, unit,    \
     desc, NO_STATE, NULL}
#define STATE(name, vr, unit, desc)                                                                      \
    {name, T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, RS(vr), 0.0, NULL, -INFINITY, INFINITY, unit,    \
     desc, NO_STATE, NULL}
#define DER(name, vr, unit, state)                                                                       \
    {"der(" name ")", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, RS(vr), 0.0, NULL, -INFINITY,         \
     INFINITY, unit, "derivative of " name, state, NULL}

/* Body n (2..6): mass, principal moments along the global axes, cg; all in the table pose. */
#define BODY(n, m, ixx, iyy, izz, x, y, z)                                                               \
    PARAM("m" #n, VR_BODY0 + ((n) - 2) * B_COUNT + B_M, m, 0, "kg", "mass of body " #n),                 \
    PARAM("Ixx" #n, VR_BODY0 + ((n) - 2) * B_COUNT + B_IXX, ixx, 0, "kg.m2",                             \
          "moment of inertia of body " #n " about its cg, global x axis in the table pose"),             \
    PARAM("Iyy" #n, VR_BODY0 + ((n) - 2) * B_COUNT + B_IYY, iyy, 0, "kg.m2",                             \
          "moment of inertia of body " #n " about its cg, global y axis in the table pose"),             \
    PARAM("Izz" #n, VR_BODY0 + ((n) - 2) * B_COUNT + B_IZZ, izz, 0, "kg.m2",                             \
          "moment of inertia of body " #n " about its cg, global z axis in the table pose"),             \
    PARAM("cg" #n "_x", VR_BODY0 + ((n) - 2) * B_COUNT + B_CGX, x, -INFINITY, "m",                       \
          "centre of gravity of body " #n " in the table pose, global x"),                               \
    PARAM("cg" #n "_y", VR_BODY0 + ((n) - 2) * B_COUNT + B_CGY, y, -INFINITY, "m",                       \
          "centre of gravity of body " #n " in the table pose, global y"),                               \
    PARAM("cg" #n "_z", VR_BODY0 + ((n) - 2) * B_COUNT + B_CGZ, z, -INFINITY, "m",                       \
          "centre of gravity of body " #n " in the table pose, global z")

/* Cylinder n (1..3): attachment point a on body ba, b on body bb (1 = ground), global, table pose. */
#define CYL_BODIES(n, ba, bb)                                                                            \
    IPARAM("cyl" #n "_body_a", VR_CYL_BODY0 + 2 * ((n) - 1), ba, 1, 6,                                   \
           "body (1 ground .. 6) carrying cylinder " #n "'s point a"),                                   \
    IPARAM("cyl" #n "_body_b", VR_CYL_BODY0 + 2 * ((n) - 1) + 1, bb, 1, 6,                               \
           "body (1 ground .. 6) carrying cylinder " #n "'s point b")
#define CYL_POINT(n, f, s, v)                                                                            \
    PARAM("cyl" #n "_" s, VR_CYL0 + ((n) - 1) * C_COUNT + (f), v, -INFINITY, "m",                        \
          "cylinder " #n " attachment point, global coordinate in the table pose")
#define CYL_POINTS(n, ax, ay, az, bx, by, bz)                                                            \
    CYL_POINT(n, C_AX, "ax", ax), CYL_POINT(n, C_AY, "ay", ay), CYL_POINT(n, C_AZ, "az", az),            \
    CYL_POINT(n, C_BX, "bx", bx), CYL_POINT(n, C_BY, "by", by), CYL_POINT(n, C_BZ, "bz", bz)

/* Defaults: Table 3 (models/mechanism/parameters.py, table3()). */
static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_AB3, 0.0),
    IPARAM("actuation", VR_ACTUATION, 0, 0, 1,
           "0: effort_k is a joint torque on q_k (N.m); 1: effort_k is the force of cylinder k (N)"),
    CYL_BODIES(1, 1, 2),
    CYL_BODIES(2, 2, 3),
    CYL_BODIES(3, 4, 3),
    STATE("v1", VR_V1, "rad", "state: independent coordinate q1"),
    STATE("v2", VR_V1 + 1, "rad", "state: independent coordinate q2"),
    STATE("v3", VR_V1 + 2, "rad", "state: independent coordinate q3"),
    STATE("vd1", VR_V1 + 3, "rad/s", "state: rate of q1"),
    STATE("vd2", VR_V1 + 4, "rad/s", "state: rate of q2"),
    STATE("vd3", VR_V1 + 5, "rad/s", "state: rate of q3"),
    DER("v1", VR_DER, "rad/s", VR_V1),
    DER("v2", VR_DER + 1, "rad/s", VR_V1 + 1),
    DER("v3", VR_DER + 2, "rad/s", VR_V1 + 2),
    DER("vd1", VR_DER + 3, "rad/s2", VR_V1 + 3),
    DER("vd2", VR_DER + 4, "rad/s2", VR_V1 + 4),
    DER("vd3", VR_DER + 5, "rad/s2", VR_V1 + 5),
    PARAM("g", VR_G, 9.81, -INFINITY, "m/s2", "gravity, acting along -z"),
    PARAM("damping1", VR_DAMP1, 0.0, 0, "N.m.s/rad", "viscous damping of joint q1"),
    PARAM("damping2", VR_DAMP1 + 1, 0.0, 0, "N.m.s/rad", "viscous damping of joint q2"),
    PARAM("damping3", VR_DAMP1 + 2, 0.0, 0, "N.m.s/rad", "viscous damping of joint q3"),
    BODY(2, 2.0, 0.7, 0.7, 0.04, 0.0, 0.0, 1.0),
    BODY(3, 2.0, 0.7, 0.04, 0.7, 0.0, 0.866, 2.503),
    BODY(4, 2.0, 0.7, 0.04, 0.7, 0.0, 2.598, 2.512),
    BODY(5, 1.5, 0.4, 0.04, 0.4, 0.0, 2.385, 1.888),
    BODY(6, 1.5, 0.4, 0.04, 0.4, 0.0, 1.084, 1.881),
    PARAM("j2_y", VR_J2Y, 0.0, -INFINITY, "m", "shoulder joint (q2) in body 2: local y"),
    PARAM("j2_z", VR_J2Z, 2.0, -INFINITY, "m", "shoulder joint (q2) in body 2: local z"),
    PARAM("j3_y", VR_J3Y, 2.0, -INFINITY, "m", "elbow joint (q3) in body 3: local y"),
    PARAM("j3_z", VR_J3Z, 0.0, -INFINITY, "m", "elbow joint (q3) in body 3: local z"),
    PARAM("j4_y", VR_J4Y, 2.0, -INFINITY, "m", "strut hinge B (q4) in body 4: local y"),
    PARAM("j4_z", VR_J4Z, -0.1, -INFINITY, "m", "strut hinge B (q4) in body 4: local z"),
    PARAM("a3_y", VR_A3Y, 0.2, -INFINITY, "m", "loop-closing pin A (joint 6-3) in body 3: local y"),
    PARAM("a3_z", VR_A3Z, -0.25, -INFINITY, "m", "loop-closing pin A (joint 6-3) in body 3: local z"),
    PARAM("q1_table", VR_QTAB1, 0.0, -INFINITY, "rad", "q1 of the pose in which body data are given"),
    PARAM("q2_table", VR_QTAB1 + 1, 30.0 * DEG, -INFINITY, "rad", "q2 of the pose in which body data are given"),
    PARAM("q3_table", VR_QTAB1 + 2, 300.0 * DEG, -INFINITY, "rad", "q3 of the pose in which body data are given"),
    PARAM("q1_0", VR_Q0_1, 0.0, -INFINITY, "rad", "initial q1"),
    PARAM("q2_0", VR_Q0_1 + 1, 30.0 * DEG, -INFINITY, "rad", "initial q2"),
    PARAM("q3_0", VR_Q0_1 + 2, 300.0 * DEG, -INFINITY, "rad", "initial q3"),
    PARAM("qd1_0", VR_QD0_1, 0.0, -INFINITY, "rad/s", "initial rate of q1"),
    PARAM("qd2_0", VR_QD0_1 + 1, 0.0, -INFINITY, "rad/s", "initial rate of q2"),
    PARAM("qd3_0", VR_QD0_1 + 2, 0.0, -INFINITY, "rad/s", "initial rate of q3"),
    CYL_POINTS(1, 0.3, -1.0, 0.5, 0.3, 0.0, 0.5),
    CYL_POINTS(2, 0.0, 0.3, 1.0, 0.0, 0.6062177826491071, 2.35),
    CYL_POINTS(3, 0.0, 3.4141016151377544, 1.9133974596215562, 0.0, 0.29820508075688774, 1.8834936490538904),
    INPUT("effort1", VR_EFFORT1, NULL, "actuator 1: torque on q1 (N.m) or cylinder 1 force (N, + extends)"),
    INPUT("effort2", VR_EFFORT1 + 1, NULL, "actuator 2: torque on q2 (N.m) or cylinder 2 force (N, + extends)"),
    INPUT("effort3", VR_EFFORT1 + 2, NULL, "actuator 3: torque on q3 (N.m) or cylinder 3 force (N, + extends)"),
    INPUT("disturbance1", VR_DIST1, "N.m", "extra joint torque on q1"),
    INPUT("disturbance2", VR_DIST1 + 1, "N.m", "extra joint torque on q2"),
    INPUT("disturbance3", VR_DIST1 + 2, "N.m", "extra joint torque on q3"),
    OUTPUT("stroke1", VR_STROKE1, NULL, "cylinder 1 length minus its initial length (m); torque mode: q1 (rad)"),
    OUTPUT("stroke2", VR_STROKE1 + 1, NULL, "cylinder 2 length minus its initial length (m); torque mode: q2 (rad)"),
    OUTPUT("stroke3", VR_STROKE1 + 2, NULL, "cylinder 3 length minus its initial length (m); torque mode: q3 (rad)"),
    OUTPUT("stroke_rate1", VR_RATE1, NULL, "time derivative of stroke1 (m/s or rad/s)"),
    OUTPUT("stroke_rate2", VR_RATE1 + 1, NULL, "time derivative of stroke2 (m/s or rad/s)"),
    OUTPUT("stroke_rate3", VR_RATE1 + 2, NULL, "time derivative of stroke3 (m/s or rad/s)"),
    OUTPUT("q1", VR_Q1, "rad", "base turn"),
    OUTPUT("q2", VR_Q1 + 1, "rad", "shoulder angle"),
    OUTPUT("q3", VR_Q1 + 2, "rad", "elbow angle"),
    OUTPUT("q4", VR_Q1 + 3, "rad", "strut hinge angle (dependent)"),
    OUTPUT("q5", VR_Q1 + 4, "m", "strut length B to A (dependent)"),
    OUTPUT("q6", VR_Q1 + 5, "rad", "strut rod turn about its axis (dependent)"),
    OUTPUT("qd1", VR_QD1, "rad/s", "rate of q1"),
    OUTPUT("qd2", VR_QD1 + 1, "rad/s", "rate of q2"),
    OUTPUT("qd3", VR_QD1 + 2, "rad/s", "rate of q3"),
    OUTPUT("qd4", VR_QD1 + 3, "rad/s", "rate of q4"),
    OUTPUT("qd5", VR_QD1 + 4, "m/s", "rate of q5"),
    OUTPUT("qd6", VR_QD1 + 5, "rad/s", "rate of q6"),
    OUTPUT("body6_x", VR_B6P, "m", "centre of gravity of body 6, global x"),
    OUTPUT("body6_y", VR_B6P + 1, "m", "centre of gravity of body 6, global y"),
    OUTPUT("body6_z", VR_B6P + 2, "m", "centre of gravity of body 6, global z"),
    OUTPUT("body6_vx", VR_B6V, "m/s", "velocity of body 6's cg, global x"),
    OUTPUT("body6_vy", VR_B6V + 1, "m/s", "velocity of body 6's cg, global y"),
    OUTPUT("body6_vz", VR_B6V + 2, "m/s", "velocity of body 6's cg, global z"),
    FORCED("body6_ax", VR_B6A, "m/s2", "acceleration of body 6's cg, global x"),
    FORCED("body6_ay", VR_B6A + 1, "m/s2", "acceleration of body 6's cg, global y"),
    FORCED("body6_az", VR_B6A + 2, "m/s2", "acceleration of body 6's cg, global z"),
    OUTPUT("energy", VR_ENERGY, "J", "kinetic plus gravitational potential energy (z = 0 datum)"),
    OUTPUT("constraint_residual", VR_RESIDUAL, NULL, "max |Phi| of the loop closure after Newton (m)"),
    LOCAL("mbar_min_eigenvalue", VR_MBAR_MIN, NULL, "smallest eigenvalue of M_bar (SI, mixed units)"),
    LOCAL("mbar_11", VR_MBAR, NULL, "reduced mass matrix M_bar, row 1 col 1"),
    LOCAL("mbar_12", VR_MBAR + 1, NULL, "M_bar row 1 col 2"),
    LOCAL("mbar_13", VR_MBAR + 2, NULL, "M_bar row 1 col 3"),
    LOCAL("mbar_21", VR_MBAR + 3, NULL, "M_bar row 2 col 1"),
    LOCAL("mbar_22", VR_MBAR + 4, NULL, "M_bar row 2 col 2"),
    LOCAL("mbar_23", VR_MBAR + 5, NULL, "M_bar row 2 col 3"),
    LOCAL("mbar_31", VR_MBAR + 6, NULL, "M_bar row 3 col 1"),
    LOCAL("mbar_32", VR_MBAR + 7, NULL, "M_bar row 3 col 2"),
    LOCAL("mbar_33", VR_MBAR + 8, NULL, "M_bar row 3 col 3"),
    LOCAL("newton_iterations", VR_NEWTON_IT, NULL, "Newton iterations of the last loop closure"),
    LOCAL("u4", VR_U, "rad", "last solved q4 (Newton warm start)"),
    LOCAL("u5", VR_U + 1, "m", "last solved q5 (Newton warm start)"),
    LOCAL("u6", VR_U + 2, "rad", "last solved q6 (Newton warm start)"),
    {"cyl1_length0", T_REAL, C_CALCULATED_PARAMETER, V_FIXED, I_CALCULATED, RS(VR_LEN0), 0.0, NULL, -INFINITY,
     INFINITY, "m", "cylinder 1 length in the initial pose (stroke 0)", NO_STATE, NULL},
    {"cyl2_length0", T_REAL, C_CALCULATED_PARAMETER, V_FIXED, I_CALCULATED, RS(VR_LEN0 + 1), 0.0, NULL,
     -INFINITY, INFINITY, "m", "cylinder 2 length in the initial pose (stroke 0)", NO_STATE, NULL},
    {"cyl3_length0", T_REAL, C_CALCULATED_PARAMETER, V_FIXED, I_CALCULATED, RS(VR_LEN0 + 2), 0.0, NULL,
     -INFINITY, INFINITY, "m", "cylinder 3 length in the initial pose (stroke 0)", NO_STATE, NULL},
};

static const int STATE_SLOTS[] = {RS(VR_V1), RS(VR_V1 + 1), RS(VR_V1 + 2),
                                  RS(VR_V1 + 3), RS(VR_V1 + 4), RS(VR_V1 + 5)};
static const int DERIVATIVE_SLOTS[] = {RS(VR_DER), RS(VR_DER + 1), RS(VR_DER + 2),
                                       RS(VR_DER + 3), RS(VR_DER + 4), RS(VR_DER + 5)};

/* ---------------------------------------------------------------- small vector algebra */

static double dot(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void cross(const double *a, const double *b, double *c)
{
    const double c0 = a[1] * b[2] - a[2] * b[1], c1 = a[2] * b[0] - a[0] * b[2], c2 = a[0] * b[1] - a[1] * b[0];
    c[0] = c0, c[1] = c1, c[2] = c2;
}

static double triple(const double *a, const double *b, const double *c)
{
    double bc[3];
    cross(b, c, bc);
    return dot(a, bc);
}

/* y = R x and y = R^T x, R row major 3x3 */
static void mv(const double *R, const double *x, double *y)
{
    for (int i = 0; i < 3; i++) y[i] = R[3 * i] * x[0] + R[3 * i + 1] * x[1] + R[3 * i + 2] * x[2];
}

static void mtv(const double *R, const double *x, double *y)
{
    for (int i = 0; i < 3; i++) y[i] = R[i] * x[0] + R[3 + i] * x[1] + R[6 + i] * x[2];
}

static void matmul(const double *A, const double *B, double *C)
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) C[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
}

static void column(const double *R, int j, double *c) { c[0] = R[j], c[1] = R[3 + j], c[2] = R[6 + j]; }

/* Elementary rotations by angle t (rad). */
static void rot(int axis, double t, double *R)
{
    const double c = cos(t), s = sin(t);
    static const double I3[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    memcpy(R, I3, sizeof I3);
    const int i = (axis + 1) % 3, j = (axis + 2) % 3; /* x: (y, z), y: (z, x), z: (x, y) */
    R[3 * i + i] = c, R[3 * i + j] = -s, R[3 * j + i] = s, R[3 * j + j] = c;
}

/* Inverse of a 3x3 matrix and its Frobenius condition number (INFINITY if singular). */
static double inverse3(const double *A, double *Ai)
{
    const double c00 = A[4] * A[8] - A[5] * A[7], c01 = A[5] * A[6] - A[3] * A[8], c02 = A[3] * A[7] - A[4] * A[6];
    const double det = A[0] * c00 + A[1] * c01 + A[2] * c02;
    if (det == 0 || !isfinite(det)) return INFINITY;
    Ai[0] = c00 / det, Ai[3] = c01 / det, Ai[6] = c02 / det;
    Ai[1] = (A[2] * A[7] - A[1] * A[8]) / det, Ai[4] = (A[0] * A[8] - A[2] * A[6]) / det;
    Ai[7] = (A[1] * A[6] - A[0] * A[7]) / det;
    Ai[2] = (A[1] * A[5] - A[2] * A[4]) / det, Ai[5] = (A[2] * A[3] - A[0] * A[5]) / det;
    Ai[8] = (A[0] * A[4] - A[1] * A[3]) / det;
    double na = 0, ni = 0;
    for (int k = 0; k < 9; k++) na += A[k] * A[k], ni += Ai[k] * Ai[k];
    return sqrt(na * ni);
}

/* Smallest eigenvalue of a symmetric 3x3 matrix (closed form, trigonometric). */
static double min_eigenvalue3(const double *A)
{
    const double p1 = A[1] * A[1] + A[2] * A[2] + A[5] * A[5];
    const double q = (A[0] + A[4] + A[8]) / 3;
    const double p2 = (A[0] - q) * (A[0] - q) + (A[4] - q) * (A[4] - q) + (A[8] - q) * (A[8] - q) + 2 * p1;
    if (p2 == 0) return q;
    const double p = sqrt(p2 / 6);
    double B[9];
    for (int k = 0; k < 9; k++) B[k] = (A[k] - (k % 4 == 0 ? q : 0)) / p;
    double r = (B[0] * (B[4] * B[8] - B[5] * B[7]) - B[1] * (B[3] * B[8] - B[5] * B[6]) +
                B[2] * (B[3] * B[7] - B[4] * B[6])) / 2;
    r = r < -1 ? -1 : (r > 1 ? 1 : r);
    return q + 2 * p * cos(acos(r) / 3 + 2 * PI / 3);
}

/* ---------------------------------------------------------------- kinematics */

typedef struct {
    double m[NB], s[NB][3], I[NB][9]; /* mass, local cg, local inertia about the cg */
    double j2[3], j3[3], j4[3], a3[3]; /* local joint points (x = 0) */
    double g;
} Params;

typedef struct {
    double R[NB][9], p[NB][3];        /* body orientation (body -> global) and frame origin */
    double Jw[NB][3][NQ], Jo[NB][3][NQ]; /* angular velocity and origin velocity per unit q-dot */
    double w[NB][3], vo[NB][3];       /* angular velocity, origin velocity */
    double al[NB][3], ao[NB][3];      /* angular and origin acceleration at q'' = 0 */
} Kin;

static void read_params(const double *r, Params *P)
{
    for (int b = 0; b < NB; b++) {
        P->m[b] = r[RS(VR_BODY0 + b * B_COUNT + B_M)];
        memcpy(P->s[b], r + H_S + 3 * b, sizeof P->s[b]);
        memcpy(P->I[b], r + H_I + 9 * b, sizeof P->I[b]);
    }
    const double j2[3] = {0, r[RS(VR_J2Y)], r[RS(VR_J2Z)]}, j3[3] = {0, r[RS(VR_J3Y)], r[RS(VR_J3Z)]};
    const double j4[3] = {0, r[RS(VR_J4Y)], r[RS(VR_J4Z)]}, a3[3] = {0, r[RS(VR_A3Y)], r[RS(VR_A3Z)]};
    memcpy(P->j2, j2, sizeof j2), memcpy(P->j3, j3, sizeof j3);
    memcpy(P->j4, j4, sizeof j4), memcpy(P->a3, a3, sizeof a3);
    P->g = r[RS(VR_G)];
}

/* Body frames, Jacobians and (if qd) velocities and velocity-product accelerations,
 * recursively from the ground.  Body index b = body number - 2. */
static void chain(const Params *P, const double *q, const double *qd, Kin *k)
{
    memset(k, 0, sizeof *k);
    rot(2, q[0], k->R[0]); /* body 2 turns about global z through the origin */
    k->Jw[0][2][0] = 1;
    if (qd) k->w[0][2] = qd[0];
    const double *jp[3] = {P->j2, P->j3, P->j4};
    for (int b = 1; b < NB; b++) {
        const int a = b - 1; /* parent */
        double r[3], ax[3], Rj[9];
        if (b < 4) { /* revolute about the parent's x axis at the parent's point jp */
            mv(k->R[a], jp[b - 1], r);
            column(k->R[a], 0, ax);
            rot(0, q[b], Rj);
        } else { /* cylindrical along body 5's y axis: slide q5, turn q6 */
            column(k->R[a], 1, ax);
            for (int i = 0; i < 3; i++) r[i] = q[4] * ax[i];
            rot(1, q[5], Rj);
        }
        matmul(k->R[a], Rj, k->R[b]);
        for (int i = 0; i < 3; i++) k->p[b][i] = k->p[a][i] + r[i];
        for (int j = 0; j < NQ; j++) {
            const double wj[3] = {k->Jw[a][0][j], k->Jw[a][1][j], k->Jw[a][2][j]};
            double c[3];
            cross(wj, r, c);
            for (int i = 0; i < 3; i++) k->Jw[b][i][j] = wj[i], k->Jo[b][i][j] = k->Jo[a][i][j] + c[i];
        }
        const int jt = b < 4 ? -1 : 4, jr = b < 4 ? b : 5; /* sliding and turning coordinates */
        for (int i = 0; i < 3; i++) {
            k->Jw[b][i][jr] += ax[i];
            if (jt >= 0) k->Jo[b][i][jt] += ax[i];
        }
        if (!qd) continue;
        double wr[3], wwr[3], alr[3], wax[3];
        cross(k->w[a], r, wr);
        cross(k->w[a], wr, wwr);
        cross(k->al[a], r, alr);
        cross(k->w[a], ax, wax);
        for (int i = 0; i < 3; i++) {
            k->w[b][i] = k->w[a][i] + ax[i] * qd[jr];
            k->vo[b][i] = k->vo[a][i] + wr[i] + (jt >= 0 ? ax[i] * qd[jt] : 0);
            k->al[b][i] = k->al[a][i] + wax[i] * qd[jr];
            k->ao[b][i] = k->ao[a][i] + alr[i] + wwr[i] + (jt >= 0 ? 2 * wax[i] * qd[jt] : 0);
        }
    }
}

/* Point fixed in body b at global position x: Jacobian (3 x NQ), velocity, acceleration at q'' = 0.
 * Any output may be NULL. */
static void point(const Kin *k, int b, const double *x, double J[3][NQ], double *v, double *a)
{
    double r[3];
    for (int i = 0; i < 3; i++) r[i] = x[i] - k->p[b][i];
    if (J) {
        for (int j = 0; j < NQ; j++) {
            const double wj[3] = {k->Jw[b][0][j], k->Jw[b][1][j], k->Jw[b][2][j]};
            double c[3];
            cross(wj, r, c);
            for (int i = 0; i < 3; i++) J[i][j] = k->Jo[b][i][j] + c[i];
        }
    }
    if (v || a) {
        double wr[3], wwr[3], alr[3];
        cross(k->w[b], r, wr);
        cross(k->w[b], wr, wwr);
        cross(k->al[b], r, alr);
        for (int i = 0; i < 3; i++) {
            if (v) v[i] = k->vo[b][i] + wr[i];
            if (a) a[i] = k->ao[b][i] + alr[i] + wwr[i];
        }
    }
}

/* Loop closure Phi (3), its Jacobian Phi_q (3 x NQ), and if `gamma` the velocity-product
 * part of d2Phi/dt2 (needs a Kin with velocities). */
static void closure(const Params *P, const Kin *k, double *phi, double Phq[3][NQ], double *gamma)
{
    double A[3], D[3], JA[3][NQ], x3[3], y3[3], z3[3], x6[3], d[3];
    mv(k->R[1], P->a3, A);
    for (int i = 0; i < 3; i++) A[i] += k->p[1][i];
    for (int i = 0; i < 3; i++) D[i] = k->p[4][i] - A[i];
    column(k->R[1], 0, x3), column(k->R[1], 1, y3), column(k->R[1], 2, z3);
    column(k->R[4], 0, x6), column(k->R[3], 1, d);
    phi[0] = dot(D, y3), phi[1] = dot(D, z3), phi[2] = triple(x6, x3, d);
    point(k, 1, A, JA, NULL, NULL);
    for (int j = 0; j < NQ; j++) {
        double dD[3], w3[3], w5[3], w6[3], dy[3], dz[3], dx6[3], dx3[3], dd[3];
        for (int i = 0; i < 3; i++) {
            dD[i] = k->Jo[4][i][j] - JA[i][j];
            w3[i] = k->Jw[1][i][j], w5[i] = k->Jw[3][i][j], w6[i] = k->Jw[4][i][j];
        }
        cross(w3, y3, dy), cross(w3, z3, dz), cross(w6, x6, dx6), cross(w3, x3, dx3), cross(w5, d, dd);
        Phq[0][j] = dot(dD, y3) + dot(D, dy);
        Phq[1][j] = dot(dD, z3) + dot(D, dz);
        Phq[2][j] = triple(dx6, x3, d) + triple(x6, dx3, d) + triple(x6, x3, dd);
    }
    if (!gamma) return;
    double vA[3], aA[3], Dd[3], Ddd[3];
    point(k, 1, A, NULL, vA, aA);
    for (int i = 0; i < 3; i++) Dd[i] = k->vo[4][i] - vA[i], Ddd[i] = k->ao[4][i] - aA[i];
    /* first and second (q'' = 0) time derivatives of a vector fixed in body b */
    double e[5][3], ed[5][3], edd[5][3];
    const double *vecs[5] = {y3, z3, x6, x3, d};
    const int body[5] = {1, 1, 4, 1, 3};
    for (int n = 0; n < 5; n++) {
        double t[3];
        const int b = body[n];
        memcpy(e[n], vecs[n], sizeof e[n]);
        cross(k->w[b], e[n], ed[n]);
        cross(k->al[b], e[n], edd[n]);
        cross(k->w[b], ed[n], t);
        for (int i = 0; i < 3; i++) edd[n][i] += t[i];
    }
    gamma[0] = dot(Ddd, y3) + 2 * dot(Dd, ed[0]) + dot(D, edd[0]);
    gamma[1] = dot(Ddd, z3) + 2 * dot(Dd, ed[1]) + dot(D, edd[1]);
    gamma[2] = triple(edd[2], e[3], e[4]) + triple(e[2], edd[3], e[4]) + triple(e[2], e[3], edd[4]) +
               2 * (triple(ed[2], ed[3], e[4]) + triple(ed[2], e[3], ed[4]) + triple(e[2], ed[3], ed[4]));
}

/* ---------------------------------------------------------------- loop closure by Newton */

/* Solve Phi(v, u) = 0 for u = q[3..5] from the guess in q; on success k holds the
 * positions and Phu_inv the inverse of Phi_u at the solution. */
static ModelStatus solve_loop(Instance *inst, const Params *P, double *q, Kin *k, double Phq[3][NQ],
                              double *Phu_inv, int *iterations, double *residual)
{
    double phi[3], Phu[9];
    for (int it = 0; it <= NEWTON_MAX_IT; it++) {
        chain(P, q, NULL, k);
        closure(P, k, phi, Phq, NULL);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) Phu[3 * i + j] = Phq[i][3 + j];
        const double res = fmax(fabs(phi[0]), fmax(fabs(phi[1]), fabs(phi[2])));
        const double cond = inverse3(Phu, Phu_inv);
        if (!isfinite(res)) {
            model_log(inst, "logError",
                      "manipulator: loop closure failed: Newton diverged (non-finite residual) at q1..q3 = "
                      "%g %g %g rad", q[0], q[1], q[2]);
            return MODEL_ERROR;
        }
        if (!(cond < COND_MAX)) {
            model_log(inst, "logError",
                      "manipulator: loop closure failed: constraint Jacobian Phi_u singular (condition %.3g, "
                      "strut length q5 = %.3g m) at q1..q3 = %g %g %g rad: singular pose of the loop",
                      cond, q[4], q[0], q[1], q[2]);
            return MODEL_ERROR;
        }
        if (res < NEWTON_TOL) {
            if (!(q[4] > 0)) {
                model_log(inst, "logError",
                          "manipulator: loop closure failed: Newton reached the flipped branch (strut length "
                          "q5 = %g m <= 0) at q1..q3 = %g %g %g rad", q[4], q[0], q[1], q[2]);
                return MODEL_ERROR;
            }
            *iterations = it;
            *residual = res;
            return MODEL_OK;
        }
        if (it == NEWTON_MAX_IT) break;
        double du[3];
        mv(Phu_inv, phi, du);
        for (int j = 0; j < 3; j++) q[3 + j] -= du[j];
    }
    model_log(inst, "logError",
              "manipulator: loop closure failed: Newton did not converge in %d iterations at q1..q3 = %g %g %g rad",
              NEWTON_MAX_IT, q[0], q[1], q[2]);
    return MODEL_ERROR;
}

/* Closed-form u for the planar loop: q5 = |A - B|, q4 = direction of A - B in body 4, q6 = 0.
 * Used only as the first Newton guess. */
static void guess_loop(const Params *P, double *q)
{
    Kin k;
    q[3] = q[4] = q[5] = 0;
    chain(P, q, NULL, &k);
    double A[3], BA[3], l[3];
    mv(k.R[1], P->a3, A);
    for (int i = 0; i < 3; i++) BA[i] = A[i] + k.p[1][i] - k.p[3][i];
    mtv(k.R[2], BA, l);
    q[3] = atan2(l[2], l[1]);
    q[4] = sqrt(dot(BA, BA));
}

/* ---------------------------------------------------------------- equations of motion */

typedef struct {
    double q[NQ], qd[NQ], qdd[NQ];
    double Mbar[9];
    double M[NQ][NQ];
    double residual;
    int iterations;
    Kin k; /* with velocities */
} Motion;

/* Generalized forces of cylinder c (force F along the line a -> b) and its length and rate. */
static void cylinder(const double *r, const int *ints, const Kin *k, const double *qd, int c, double *dl,
                     double *len, double *rate)
{
    double x[2][3], J[2][3][NQ], v[2][3];
    for (int e = 0; e < 2; e++) {
        const int b = ints[I_CYL_BODY0 + 2 * c + e] - 2; /* -1: ground */
        const double *loc = r + H_CP + 6 * c + 3 * e;
        if (b < 0) {
            memcpy(x[e], loc, sizeof x[e]);
            memset(J[e], 0, sizeof J[e]);
            memset(v[e], 0, sizeof v[e]);
        } else {
            mv(k->R[b], loc, x[e]);
            for (int i = 0; i < 3; i++) x[e][i] += k->p[b][i];
            point(k, b, x[e], J[e], qd ? v[e] : NULL, NULL);
        }
    }
    double u[3];
    for (int i = 0; i < 3; i++) u[i] = x[1][i] - x[0][i];
    *len = sqrt(dot(u, u));
    for (int i = 0; i < 3; i++) u[i] /= *len;
    for (int j = 0; j < NQ; j++) {
        dl[j] = 0;
        for (int i = 0; i < 3; i++) dl[j] += u[i] * (J[1][i][j] - J[0][i][j]);
    }
    if (rate) {
        double dv[3];
        for (int i = 0; i < 3; i++) dv[i] = v[1][i] - v[0][i];
        *rate = dot(u, dv);
    }
}

/* Everything at state x = (v, v'): loop closure, reduced equations (8)-(10), v''. */
static ModelStatus motion(Instance *inst, const double *x, Motion *mo)
{
    double *r = model_reals(inst);
    const int *ints = model_integers(inst);
    Params P;
    read_params(r, &P);
    double *q = mo->q, *qd = mo->qd, Phq[3][NQ], Phu_inv[9], gamma[3];
    for (int j = 0; j < 3; j++) q[j] = x[j], qd[j] = x[3 + j], q[3 + j] = r[RS(VR_U + j)];
    if (solve_loop(inst, &P, q, &mo->k, Phq, Phu_inv, &mo->iterations, &mo->residual) != MODEL_OK)
        return MODEL_ERROR;
    for (int j = 0; j < 3; j++) r[RS(VR_U + j)] = q[3 + j];
    /* R1 = -Phi_u^-1 Phi_v (eq. 6), u' = R1 v' */
    double R1[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            R1[i][j] = -(Phu_inv[3 * i] * Phq[0][j] + Phu_inv[3 * i + 1] * Phq[1][j] + Phu_inv[3 * i + 2] * Phq[2][j]);
    for (int i = 0; i < 3; i++) qd[3 + i] = R1[i][0] * qd[0] + R1[i][1] * qd[1] + R1[i][2] * qd[2];
    Kin *k = &mo->k;
    chain(&P, q, qd, k);
    double phi[3];
    closure(&P, k, phi, Phq, gamma);
    double R2[3]; /* eq. 7: u'' = R1 v'' + R2 */
    mv(Phu_inv, gamma, R2);
    for (int i = 0; i < 3; i++) R2[i] = -R2[i];

    /* M and Q from body Jacobians */
    double (*M)[NQ] = mo->M, Q[NQ] = {0};
    memset(mo->M, 0, sizeof mo->M);
    for (int b = 0; b < NB; b++) {
        double rho[3], c[3], Jc[3][NQ], ac[3], Ig[9], T[9], Iw[3], f[3], tau[3], wIw[3], Ial[3];
        mv(k->R[b], P.s[b], rho);
        for (int i = 0; i < 3; i++) c[i] = k->p[b][i] + rho[i];
        point(k, b, c, Jc, NULL, ac);
        /* Ig = R I R^T */
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                T[3 * i + j] = P.I[b][3 * i] * k->R[b][3 * j] + P.I[b][3 * i + 1] * k->R[b][3 * j + 1] +
                               P.I[b][3 * i + 2] * k->R[b][3 * j + 2];
        matmul(k->R[b], T, Ig);
        mv(Ig, k->w[b], Iw);
        cross(k->w[b], Iw, wIw);
        mv(Ig, k->al[b], Ial);
        const double m = P.m[b];
        for (int i = 0; i < 3; i++) f[i] = -m * ac[i], tau[i] = -Ial[i] - wIw[i];
        f[2] -= m * P.g;
        double IJ[3][NQ]; /* Ig Jw */
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < NQ; j++)
                IJ[i][j] = Ig[3 * i] * k->Jw[b][0][j] + Ig[3 * i + 1] * k->Jw[b][1][j] + Ig[3 * i + 2] * k->Jw[b][2][j];
        for (int a = 0; a < NQ; a++) {
            for (int j = 0; j < NQ; j++) {
                double s = 0;
                for (int i = 0; i < 3; i++) s += m * Jc[i][a] * Jc[i][j] + k->Jw[b][i][a] * IJ[i][j];
                M[a][j] += s;
            }
            for (int i = 0; i < 3; i++) Q[a] += Jc[i][a] * f[i] + k->Jw[b][i][a] * tau[i];
        }
    }
    /* applied efforts */
    for (int j = 0; j < 3; j++) Q[j] += r[RS(VR_DIST1 + j)] - r[RS(VR_DAMP1 + j)] * qd[j];
    if (ints[I_ACTUATION] == 0) {
        for (int j = 0; j < 3; j++) Q[j] += r[RS(VR_EFFORT1 + j)];
    } else {
        for (int c = 0; c < NCYL; c++) {
            double dl[NQ], len;
            cylinder(r, ints, k, NULL, c, dl, &len, NULL);
            for (int j = 0; j < NQ; j++) Q[j] += r[RS(VR_EFFORT1 + c)] * dl[j];
        }
    }
    /* eqs. (9), (10) with v = q[0..2], u = q[3..5] */
    double Qbar[3];
    for (int a = 0; a < 3; a++) {
        double MuR2 = 0;
        for (int i = 0; i < 3; i++) MuR2 += M[a][3 + i] * R2[i]; /* (Mvu R2)_a */
        Qbar[a] = Q[a] - MuR2;
        for (int i = 0; i < 3; i++) {
            double MuuR2 = 0;
            for (int l = 0; l < 3; l++) MuuR2 += M[3 + i][3 + l] * R2[l];
            Qbar[a] += R1[i][a] * (Q[3 + i] - MuuR2);
        }
        for (int c = 0; c < 3; c++) {
            double s = M[a][c];
            for (int i = 0; i < 3; i++) {
                s += M[a][3 + i] * R1[i][c] + R1[i][a] * M[3 + i][c];
                for (int l = 0; l < 3; l++) s += R1[i][a] * M[3 + i][3 + l] * R1[l][c];
            }
            mo->Mbar[3 * a + c] = s;
        }
    }
    /* Cholesky M_bar = L L^T, then v'' */
    const double *A = mo->Mbar;
    double L[9] = {0};
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j <= i; j++) {
            double s = A[3 * i + j];
            for (int l = 0; l < j; l++) s -= L[3 * i + l] * L[3 * j + l];
            if (i == j) {
                if (!(s > 0)) {
                    model_log(inst, "logError",
                              "manipulator: reduced mass matrix M_bar is not positive definite (pivot %g) at "
                              "q1..q3 = %g %g %g rad", s, q[0], q[1], q[2]);
                    return MODEL_ERROR;
                }
                L[3 * i + i] = sqrt(s);
            } else {
                L[3 * i + j] = s / L[3 * j + j];
            }
        }
    }
    double y[3];
    for (int i = 0; i < 3; i++) {
        y[i] = Qbar[i];
        for (int l = 0; l < i; l++) y[i] -= L[3 * i + l] * y[l];
        y[i] /= L[3 * i + i];
    }
    for (int i = 2; i >= 0; i--) {
        double s = y[i];
        for (int l = i + 1; l < 3; l++) s -= L[3 * l + i] * mo->qdd[l];
        mo->qdd[i] = s / L[3 * i + i];
    }
    for (int i = 0; i < 3; i++)
        mo->qdd[3 + i] = R1[i][0] * mo->qdd[0] + R1[i][1] * mo->qdd[1] + R1[i][2] * mo->qdd[2] + R2[i];
    return MODEL_OK;
}

/* ---------------------------------------------------------------- model interface */

static ModelStatus check_param(Instance *inst, int vr, int positive)
{
    const double v = model_reals(inst)[RS(vr)];
    if (!isfinite(v) || (positive && !(v > 0))) {
        model_log(inst, "logError", "manipulator: parameter %s = %g must be %s", VARIABLES[vr].name, v,
                  positive ? "positive and finite" : "finite");
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

/* Body data to local frames (from the table pose), initial state and warm start. */
static ModelStatus initialize(Instance *inst)
{
    double *r = model_reals(inst);
    int *ints = model_integers(inst);
    for (int vr = VR_G; vr < VR_EFFORT1; vr++) {
        const int off = vr - VR_BODY0;
        const int pos = off >= 0 && off < NB * B_COUNT && off % B_COUNT <= B_IZZ;
        if (check_param(inst, vr, pos) != MODEL_OK) return MODEL_ERROR;
    }
    for (int b = 0; b < NB; b++) {
        const double *I = r + RS(VR_BODY0 + b * B_COUNT + B_IXX);
        for (int i = 0; i < 3; i++) {
            if (I[i] > (I[(i + 1) % 3] + I[(i + 2) % 3]) * (1 + 1e-12)) {
                model_log(inst, "logError",
                          "manipulator: body %d: %s = %g exceeds the sum of the other two moments (%g): not a "
                          "rigid body", b + 2, VARIABLES[VR_BODY0 + b * B_COUNT + B_IXX + i].name, I[i],
                          I[(i + 1) % 3] + I[(i + 2) % 3]);
                return MODEL_ERROR;
            }
        }
    }
    Params P;
    read_params(r, &P);
    Kin k;
    double q[NQ] = {r[RS(VR_QTAB1)], r[RS(VR_QTAB1 + 1)], r[RS(VR_QTAB1 + 2)], 0, 0, 0}, Phq[3][NQ], Pi[9], res;
    int it;
    guess_loop(&P, q);
    if (solve_loop(inst, &P, q, &k, Phq, Pi, &it, &res) != MODEL_OK) {
        model_log(inst, "logError", "manipulator: the table pose q*_table does not close the loop");
        return MODEL_ERROR;
    }
    for (int b = 0; b < NB; b++) {
        const double *B = r + RS(VR_BODY0 + b * B_COUNT);
        const double cg[3] = {B[B_CGX], B[B_CGY], B[B_CGZ]}, D[9] = {B[B_IXX], 0, 0, 0, B[B_IYY], 0, 0, 0, B[B_IZZ]};
        double rel[3], T[9], Rt[9];
        for (int i = 0; i < 3; i++) rel[i] = cg[i] - k.p[b][i];
        mtv(k.R[b], rel, r + H_S + 3 * b);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) Rt[3 * i + j] = k.R[b][3 * j + i];
        matmul(Rt, D, T); /* I_local = R^T D R */
        matmul(T, k.R[b], r + H_I + 9 * b);
    }
    for (int c = 0; c < NCYL; c++) {
        for (int e = 0; e < 2; e++) {
            const int b = ints[I_CYL_BODY0 + 2 * c + e] - 2;
            const double *gp = r + RS(VR_CYL0 + c * C_COUNT + 3 * e);
            double *loc = r + H_CP + 6 * c + 3 * e;
            if (b < 0) {
                memcpy(loc, gp, 3 * sizeof *loc);
            } else {
                double rel[3];
                for (int i = 0; i < 3; i++) rel[i] = gp[i] - k.p[b][i];
                mtv(k.R[b], rel, loc);
            }
        }
    }
    /* initial pose */
    for (int j = 0; j < 3; j++) q[j] = r[RS(VR_Q0_1 + j)];
    guess_loop(&P, q);
    if (solve_loop(inst, &P, q, &k, Phq, Pi, &it, &res) != MODEL_OK) {
        model_log(inst, "logError", "manipulator: the initial pose q*_0 does not close the loop");
        return MODEL_ERROR;
    }
    for (int j = 0; j < 3; j++) {
        r[RS(VR_U + j)] = q[3 + j];
        r[RS(VR_V1 + j)] = r[RS(VR_Q0_1 + j)];
        r[RS(VR_V1 + 3 + j)] = r[RS(VR_QD0_1 + j)];
    }
    for (int c = 0; c < NCYL; c++) {
        double dl[NQ], len;
        if (ints[I_CYL_BODY0 + 2 * c] == ints[I_CYL_BODY0 + 2 * c + 1]) {
            if (ints[I_ACTUATION] == 0) { r[RS(VR_LEN0 + c)] = 0; continue; }
            model_log(inst, "logError", "manipulator: cylinder %d: cyl%d_body_a = cyl%d_body_b = %d; it needs two bodies",
                      c + 1, c + 1, c + 1, ints[I_CYL_BODY0 + 2 * c]);
            return MODEL_ERROR;
        }
        cylinder(r, ints, &k, NULL, c, dl, &len, NULL);
        if (!(len > 1e-6) && ints[I_ACTUATION] == 1) {
            model_log(inst, "logError", "manipulator: cylinder %d: attachment points coincide (length %g m)", c + 1, len);
            return MODEL_ERROR;
        }
        r[RS(VR_LEN0 + c)] = len;
    }
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx)
{
    (void)t;
    Motion mo;
    if (motion(inst, x, &mo) != MODEL_OK) return MODEL_ERROR;
    for (int j = 0; j < 3; j++) dx[j] = x[3 + j], dx[3 + j] = mo.qdd[j];
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x)
{
    (void)t;
    double *r = model_reals(inst);
    const int *ints = model_integers(inst);
    Motion mo;
    if (motion(inst, x, &mo) != MODEL_OK) return MODEL_ERROR;
    const Kin *k = &mo.k;
    for (int j = 0; j < NQ; j++) r[RS(VR_Q1 + j)] = mo.q[j], r[RS(VR_QD1 + j)] = mo.qd[j];
    for (int j = 0; j < 3; j++) r[RS(VR_DER + j)] = x[3 + j], r[RS(VR_DER + 3 + j)] = mo.qdd[j];
    /* body 6 cg and energy */
    double energy = 0;
    for (int b = 0; b < NB; b++) {
        double rho[3], c[3], J[3][NQ], v[3], a[3], Ig[9], T[9], Rt[9], Iw[3];
        const double *s = r + H_S + 3 * b;
        mv(k->R[b], s, rho);
        for (int i = 0; i < 3; i++) c[i] = k->p[b][i] + rho[i];
        point(k, b, c, J, v, a);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < NQ; j++) a[i] += J[i][j] * mo.qdd[j];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) Rt[3 * i + j] = k->R[b][3 * j + i];
        matmul(k->R[b], r + H_I + 9 * b, T);
        matmul(T, Rt, Ig);
        mv(Ig, k->w[b], Iw);
        const double m = r[RS(VR_BODY0 + b * B_COUNT + B_M)];
        energy += 0.5 * m * dot(v, v) + 0.5 * dot(k->w[b], Iw) + m * r[RS(VR_G)] * c[2];
        if (b == NB - 1) {
            for (int i = 0; i < 3; i++) r[RS(VR_B6P + i)] = c[i], r[RS(VR_B6V + i)] = v[i], r[RS(VR_B6A + i)] = a[i];
        }
    }
    r[RS(VR_ENERGY)] = energy;
    r[RS(VR_RESIDUAL)] = mo.residual;
    r[RS(VR_NEWTON_IT)] = mo.iterations;
    memcpy(r + RS(VR_MBAR), mo.Mbar, sizeof mo.Mbar);
    double S[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) S[3 * i + j] = 0.5 * (mo.Mbar[3 * i + j] + mo.Mbar[3 * j + i]);
    r[RS(VR_MBAR_MIN)] = min_eigenvalue3(S);
    for (int c = 0; c < NCYL; c++) {
        if (ints[I_ACTUATION] == 0) {
            r[RS(VR_STROKE1 + c)] = mo.q[c], r[RS(VR_RATE1 + c)] = mo.qd[c];
        } else {
            double dl[NQ], len, rate;
            cylinder(r, ints, k, mo.qd, c, dl, &len, &rate);
            r[RS(VR_STROKE1 + c)] = len - r[RS(VR_LEN0 + c)], r[RS(VR_RATE1 + c)] = rate;
        }
    }
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "manipulator",
    .guid = "{5d0c8a3e-7b1f-4c62-9e84-2f6a1b9d3c70}",
    .description = "Six-body manipulator with a closed loop (coordinate partitioning, paper eqs. 6-10)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .n_booleans = 0,
    .n_strings = 0,
    .n_states = 6,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = NULL,
    .outputs = outputs,
    .outputs_give_derivatives = 1, /* outputs() runs motion() as derivatives() does */
    .autonomous = 1,
};
