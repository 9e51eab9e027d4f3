/* alltypes: one input, one output (and for numbers one parameter) of every FMI 3.0 type, arrays,
 * a continuous state and a stop request: the test FMU of the FMI 3.0 layer (FMI 3.0 only).
 *
 * Outputs, computed from the inputs, parameters and time (at the end of every step, and
 * whenever an input changed):
 *   y_float32 = u_float32 + p_float32       in float arithmetic (IEEE, rounded to float)
 *   y_float64 = u_float64 + p_float64       (a float sum beyond the range is inf, which the
 *                                           layer reports as a failed step, as for any output)
 *   y_<int>   = u_<int> + p_<int>           saturated at the type's range, for int8, uint8,
 *                                           int16, uint16, int32, uint32, int64, uint64
 *   y_boolean = !u_boolean
 *   y_string  = u_string + "!"              cut to 2047 bytes
 *   y_binary  = the bytes of u_binary in reverse order
 *   y_enumeration = u_enumeration mod 6 + 1 (Enumeration "Solver", values 1..6: the next one)
 *   y_vec     = 2 u_vec                     (Float64 vectors of 3)
 *   y_mat     = p_mat transposed            (Float64 2x2 matrices, row major)
 *   y_ivec    = u_ivec + p_int32            (Int32 vectors of 2, saturated)
 *   wave      = (sin t, cos 3t, t^3)        (a Float64 vector of 3 that depends on time only)
 *   ticks     = (k, -2 k), k = round(10 t)  (an Int32 vector of 2 that depends on time only)
 *   stamp     = k % 3 + 1 bytes of value k % 256, then a zero byte (a Binary that depends on time
 *               only: its length changes, and it ends in a zero)
 *   x' = u_float64, x(0) = 0                (continuous state, output x)
 * When the step that reaches t >= stop_at completes, the model ends the simulation
 * (fmi3DoStep: fmi3OK with *terminateSimulation = fmi3True).
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "model.h"

enum {
    VR_SOLVER,
    VR_INTERNAL_STEP,
    VR_U_FLOAT32, VR_Y_FLOAT32, VR_P_FLOAT32,
    VR_U_FLOAT64, VR_Y_FLOAT64, VR_P_FLOAT64,
    VR_U_INT8, VR_Y_INT8, VR_P_INT8,
    VR_U_UINT8, VR_Y_UINT8, VR_P_UINT8,
    VR_U_INT16, VR_Y_INT16, VR_P_INT16,
    VR_U_UINT16, VR_Y_UINT16, VR_P_UINT16,
    VR_U_INT32, VR_Y_INT32, VR_P_INT32,
    VR_U_UINT32, VR_Y_UINT32, VR_P_UINT32,
    VR_U_INT64, VR_Y_INT64, VR_P_INT64,
    VR_U_UINT64, VR_Y_UINT64, VR_P_UINT64,
    VR_U_BOOLEAN, VR_Y_BOOLEAN,
    VR_U_STRING, VR_Y_STRING,
    VR_U_BINARY, VR_Y_BINARY,
    VR_U_ENUMERATION, VR_Y_ENUMERATION,
    VR_U_VEC, VR_Y_VEC,
    VR_P_MAT, VR_Y_MAT,
    VR_STOP_AT,
    VR_X, VR_DER_X,
    VR_U_IVEC, VR_Y_IVEC, VR_WAVE, VR_TICKS, VR_STAMP,
    N_VARIABLES
};

/* Real slots (Float32 and Float64), int slots (Int32, Enumeration), int64 slots (the other
 * integers but UInt64), uint64 slots, boolean, string and binary slots. */
enum {
    R_U_FLOAT32 = R_MODEL_START, R_Y_FLOAT32, R_P_FLOAT32,
    R_U_FLOAT64, R_Y_FLOAT64, R_P_FLOAT64,
    R_STOP_AT, R_X, R_DER_X,
    R_U_VEC, R_Y_VEC = R_U_VEC + 3, R_P_MAT = R_Y_VEC + 3, R_Y_MAT = R_P_MAT + 4, R_WAVE = R_Y_MAT + 4,
    N_REALS = R_WAVE + 3
};
enum {
    I_U_INT32 = I_MODEL_START, I_Y_INT32, I_P_INT32, I_U_ENUMERATION, I_Y_ENUMERATION,
    I_U_IVEC, I_Y_IVEC = I_U_IVEC + 2, I_TICKS = I_Y_IVEC + 2,
    N_INTEGERS = I_TICKS + 2
};
enum { W_INT8, W_UINT8 = 3, W_INT16 = 6, W_UINT16 = 9, W_UINT32 = 12, W_INT64 = 15, N_INT64S = 18 }; /* u, y, p */
enum { Q_U_UINT64, Q_Y_UINT64, Q_P_UINT64, N_UINT64S };
enum { B_U, B_Y, N_BOOLEANS };
enum { S_U, S_Y, N_STRINGS };
enum { X_U, X_Y, X_STAMP, N_BINARIES };

/* The dependency strings below name value references literally: keep them in step. */
#define SAME(a, b) typedef char same_##a[(a) == (b) ? 1 : -1]
SAME(VR_U_FLOAT32, 2);
SAME(VR_U_FLOAT64, 5);
SAME(VR_U_INT8, 8);
SAME(VR_U_UINT8, 11);
SAME(VR_U_INT16, 14);
SAME(VR_U_UINT16, 17);
SAME(VR_U_INT32, 20);
SAME(VR_U_UINT32, 23);
SAME(VR_U_INT64, 26);
SAME(VR_U_UINT64, 29);
SAME(VR_U_BOOLEAN, 32);
SAME(VR_U_STRING, 34);
SAME(VR_U_BINARY, 36);
SAME(VR_U_ENUMERATION, 38);
SAME(VR_U_VEC, 40);
SAME(VR_U_IVEC, 47);
SAME(N_VARIABLES, 52);

#define INPUT(name, type, variability, slot, start, start_string, description)                                 \
    {name, type, C_INPUT, variability, I_DEFAULT, slot, start, start_string, -INFINITY, INFINITY, NULL,        \
     description, NO_STATE, NULL}
#define OUTPUT(name, type, variability, slot, description, dependencies)                                       \
    {name, type, C_OUTPUT, variability, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, NULL, description, \
     NO_STATE, dependencies}
#define PARAMETER(name, type, slot, start, description)                                                        \
    {name, type, C_PARAMETER, V_FIXED, I_EXACT, slot, start, NULL, -INFINITY, INFINITY, NULL, description,     \
     NO_STATE, NULL}
/* u_<T>, y_<T> = u_<T> + p_<T>, p_<T> of a number type; `u` is the value reference of u_<T>. */
#define NUMBER(T, type, variability, u, slot_u, slot_y, slot_p, p_start, rule)                                  \
    INPUT("u_" T, type, variability, slot_u, 0.0, NULL, T " input"),                                              \
    OUTPUT("y_" T, type, variability, slot_y, rule, #u),                                                         \
    PARAMETER("p_" T, type, slot_p, p_start, "added to u_" T)

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    NUMBER("float32", T_FLOAT32, V_CONTINUOUS, 2, R_U_FLOAT32, R_Y_FLOAT32, R_P_FLOAT32, 0.25,
           "u + p in float arithmetic"),
    NUMBER("float64", T_FLOAT64, V_CONTINUOUS, 5, R_U_FLOAT64, R_Y_FLOAT64, R_P_FLOAT64, 1.5, "u + p"),
    NUMBER("int8", T_INT8, V_DISCRETE, 8, W_INT8, W_INT8 + 1, W_INT8 + 2, 1, "u + p, saturated"),
    NUMBER("uint8", T_UINT8, V_DISCRETE, 11, W_UINT8, W_UINT8 + 1, W_UINT8 + 2, 1, "u + p, saturated"),
    NUMBER("int16", T_INT16, V_DISCRETE, 14, W_INT16, W_INT16 + 1, W_INT16 + 2, 1, "u + p, saturated"),
    NUMBER("uint16", T_UINT16, V_DISCRETE, 17, W_UINT16, W_UINT16 + 1, W_UINT16 + 2, 1, "u + p, saturated"),
    NUMBER("int32", T_INT32, V_DISCRETE, 20, I_U_INT32, I_Y_INT32, I_P_INT32, 1, "u + p, saturated"),
    NUMBER("uint32", T_UINT32, V_DISCRETE, 23, W_UINT32, W_UINT32 + 1, W_UINT32 + 2, 1, "u + p, saturated"),
    NUMBER("int64", T_INT64, V_DISCRETE, 26, W_INT64, W_INT64 + 1, W_INT64 + 2, 1, "u + p, saturated"),
    NUMBER("uint64", T_UINT64, V_DISCRETE, 29, Q_U_UINT64, Q_Y_UINT64, Q_P_UINT64, 1, "u + p, saturated"),
    INPUT("u_boolean", T_BOOLEAN, V_DISCRETE, B_U, 0.0, NULL, "Boolean input"),
    OUTPUT("y_boolean", T_BOOLEAN, V_DISCRETE, B_Y, "not u", "32"),
    INPUT("u_string", T_STRING, V_DISCRETE, S_U, 0.0, "abc", "String input"),
    OUTPUT("y_string", T_STRING, V_DISCRETE, S_Y, "u followed by \"!\", cut to 2047 bytes", "34"),
    INPUT("u_binary", T_BINARY, V_DISCRETE, X_U, 0.0, "00ff", "Binary input"),
    OUTPUT("y_binary", T_BINARY, V_DISCRETE, X_Y, "the bytes of u in reverse order", "36"),
    {"u_enumeration", T_SOLVER, C_INPUT, V_DISCRETE, I_DEFAULT, I_U_ENUMERATION, 1, NULL, 1, SOLVER_COUNT, NULL,
     "Enumeration input (type Solver)", NO_STATE, NULL},
    OUTPUT("y_enumeration", T_SOLVER, V_DISCRETE, I_Y_ENUMERATION, "u mod 6 + 1: the next item", "38"),
    INPUT("u_vec", T_FLOAT64, V_CONTINUOUS, R_U_VEC, 0.0, NULL, "Float64 vector input"),
    OUTPUT("y_vec", T_FLOAT64, V_CONTINUOUS, R_Y_VEC, "2 u_vec", "40"),
    PARAMETER("p_mat", T_FLOAT64, R_P_MAT, 1.0, "a 2x2 matrix (row major)"),
    OUTPUT("y_mat", T_FLOAT64, V_CONTINUOUS, R_Y_MAT, "p_mat transposed", ""),
    {"stop_at", T_FLOAT64, C_PARAMETER, V_FIXED, I_EXACT, R_STOP_AT, 1e300, NULL, -INFINITY, INFINITY, "s",
     "the step that reaches this time ends the simulation", NO_STATE, NULL},
    {"x", T_FLOAT64, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_X, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "state: the integral of u_float64, x(0) = 0", NO_STATE, "states"},
    {"der(x)", T_FLOAT64, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_X, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "derivative of x: u_float64", VR_X, "5"},
    INPUT("u_ivec", T_INT32, V_DISCRETE, I_U_IVEC, 0.0, NULL, "Int32 vector input"),
    OUTPUT("y_ivec", T_INT32, V_DISCRETE, I_Y_IVEC, "u_ivec + p_int32, saturated", "47"),
    OUTPUT("wave", T_FLOAT64, V_CONTINUOUS, R_WAVE, "(sin t, cos 3t, t^3)", ""),
    OUTPUT("ticks", T_INT32, V_DISCRETE, I_TICKS, "(k, -2 k), k = round(10 t)", ""),
    OUTPUT("stamp", T_BINARY, V_DISCRETE, X_STAMP, "k % 3 + 1 bytes k % 256, then a zero, k = round(10 t)", ""),
};

static const int DIMENSIONS[N_VARIABLES][MAX_DIMENSIONS] = {
    [VR_U_VEC] = {3}, [VR_Y_VEC] = {3}, [VR_P_MAT] = {2, 2}, [VR_Y_MAT] = {2, 2},
    [VR_U_IVEC] = {2}, [VR_Y_IVEC] = {2}, [VR_WAVE] = {3}, [VR_TICKS] = {2}};

static const int STATE_SLOTS[] = {R_X};
static const int DERIVATIVE_SLOTS[] = {R_DER_X};

static int64_t clamp(int64_t v, int64_t lo, int64_t hi) { return v < lo ? lo : v > hi ? hi : v; }

static int64_t add_int64(int64_t a, int64_t b) {
    if (b > 0 && a > INT64_MAX - b) return INT64_MAX;
    if (b < 0 && a < INT64_MIN - b) return INT64_MIN;
    return a + b;
}

static uint64_t add_uint64(uint64_t a, uint64_t b) { return a + b < a ? UINT64_MAX : a + b; }

static ModelStatus initialize(Instance *inst) {
    model_reals(inst)[R_X] = 0.0;
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx) {
    (void)t, (void)x;
    dx[0] = model_reals(inst)[R_U_FLOAT64];
    return MODEL_OK;
}

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    double *r = model_reals(inst);
    int *n = model_integers(inst);
    int64_t *w = model_int64s(inst);
    uint64_t *q = model_uint64s(inst);
    int *b = model_booleans(inst);
    const char *u_string = model_string(inst, S_U);
    char text[STRING_CAPACITY + 1];
    const unsigned char *u_bytes;
    unsigned char reversed[BINARY_CAPACITY];
    size_t size, length = strlen(u_string);
    (void)x;

    r[R_Y_FLOAT32] = (float)((float)r[R_U_FLOAT32] + (float)r[R_P_FLOAT32]);
    r[R_Y_FLOAT64] = r[R_U_FLOAT64] + r[R_P_FLOAT64];
    /* u and p hold values of their type (the layer takes nothing else), so the sums of the
     * narrower types fit into 64 bits before they are saturated. */
    w[W_INT8 + 1] = clamp(w[W_INT8] + w[W_INT8 + 2], INT8_MIN, INT8_MAX);
    w[W_UINT8 + 1] = clamp(w[W_UINT8] + w[W_UINT8 + 2], 0, UINT8_MAX);
    w[W_INT16 + 1] = clamp(w[W_INT16] + w[W_INT16 + 2], INT16_MIN, INT16_MAX);
    w[W_UINT16 + 1] = clamp(w[W_UINT16] + w[W_UINT16 + 2], 0, UINT16_MAX);
    n[I_Y_INT32] = (int)clamp((int64_t)n[I_U_INT32] + n[I_P_INT32], INT32_MIN, INT32_MAX);
    w[W_UINT32 + 1] = clamp(w[W_UINT32] + w[W_UINT32 + 2], 0, UINT32_MAX);
    w[W_INT64 + 1] = add_int64(w[W_INT64], w[W_INT64 + 2]);
    q[Q_Y_UINT64] = add_uint64(q[Q_U_UINT64], q[Q_P_UINT64]);
    b[B_Y] = !b[B_U];

    memcpy(text, u_string, length);
    text[length] = '!';
    text[length + 1] = '\0';
    model_set_string(inst, S_Y, text); /* cut to STRING_CAPACITY - 1 bytes */

    u_bytes = model_binary(inst, X_U, &size);
    for (size_t k = 0; k < size; k++) reversed[k] = u_bytes[size - 1 - k];
    model_set_binary(inst, X_Y, reversed, size);

    n[I_Y_ENUMERATION] = n[I_U_ENUMERATION] % SOLVER_COUNT + 1;
    for (int k = 0; k < 3; k++) r[R_Y_VEC + k] = 2.0 * r[R_U_VEC + k];
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) r[R_Y_MAT + 2 * i + j] = r[R_P_MAT + 2 * j + i];
    for (int k = 0; k < 2; k++)
        n[I_Y_IVEC + k] = (int)clamp((int64_t)n[I_U_IVEC + k] + n[I_P_INT32], INT32_MIN, INT32_MAX);
    r[R_WAVE] = sin(t);
    r[R_WAVE + 1] = cos(3.0 * t);
    r[R_WAVE + 2] = t * t * t;
    n[I_TICKS] = (int)floor(10.0 * t + 0.5);
    n[I_TICKS + 1] = -2 * n[I_TICKS];
    size = (size_t)(n[I_TICKS] % 3 + 1);
    memset(reversed, n[I_TICKS] & 0xff, size);
    reversed[size] = 0;
    model_set_binary(inst, X_STAMP, reversed, size + 1);
    return t >= r[R_STOP_AT] ? MODEL_TERMINATE : MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "alltypes",
    .guid = "{7e4a2c19-3b85-4d6f-a0e2-5c9b1d8f4a36}",
    .description = "An input, an output and a parameter of every FMI 3.0 type, arrays, a state, a stop request",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .n_booleans = N_BOOLEANS,
    .n_strings = N_STRINGS,
    .n_int64s = N_INT64S,
    .n_uint64s = N_UINT64S,
    .n_binaries = N_BINARIES,
    .dimensions = DIMENSIONS,
    .fmi3_only = 1,
    .n_states = 1,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = NULL,
    .outputs = outputs,
};
