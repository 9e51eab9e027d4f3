/* text: String signals, for testing String connections (held between communication points).
 * Builds as FMI 2.0 and as FMI 3.0; no state.
 *
 *   y_string = u_string followed by `repeat` copies of `suffix` (none when repeat <= 0), cut to
 *              STRING_CAPACITY - 1 bytes
 *   y_length = the number of bytes of u_string                       (Integer)
 *   y_code   = sum over the bytes b_i of u_string of (i + 1) b_i, modulo 1000003 (Integer: a
 *              checksum that tells strings of one length apart)
 *   y        = u                                                     (Real: makes the FMU an
 *              output-depends-on-input component for the resampling tests)
 */
#include <string.h>

#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_SUFFIX, VR_U_STRING, VR_REPEAT, VR_U, VR_Y_STRING, VR_Y_LENGTH, VR_Y_CODE,
       VR_Y, N_VARIABLES };

enum { R_U = R_MODEL_START, R_Y, N_REALS };
enum { I_REPEAT = I_MODEL_START, I_Y_LENGTH, I_Y_CODE, N_INTEGERS };
enum { S_SUFFIX, S_U, S_Y, N_STRINGS };

/* The dependency strings below name value references literally: keep them in step. */
#define SAME(a, b) typedef char same_##a[(a) == (b) ? 1 : -1]
SAME(VR_U_STRING, 3);
SAME(VR_REPEAT, 4);
SAME(VR_U, 5);

#define CODE_MODULUS 1000003u

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"suffix", T_STRING, C_PARAMETER, V_FIXED, I_EXACT, S_SUFFIX, 0.0, "!", -INFINITY, INFINITY, NULL,
     "appended to u_string, repeat times", NO_STATE, NULL},
    {"u_string", T_STRING, C_INPUT, V_DISCRETE, I_DEFAULT, S_U, 0.0, "", -INFINITY, INFINITY, NULL,
     "String input", NO_STATE, NULL},
    {"repeat", T_INTEGER, C_INPUT, V_DISCRETE, I_DEFAULT, I_REPEAT, 1, NULL, -INFINITY, INFINITY, NULL,
     "copies of suffix in y_string", NO_STATE, NULL},
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U, 0.0, NULL, -INFINITY, INFINITY, NULL, "Real input",
     NO_STATE, NULL},
    {"y_string", T_STRING, C_OUTPUT, V_DISCRETE, I_CALCULATED, S_Y, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "u_string followed by repeat copies of suffix", NO_STATE, "3 4"},
    {"y_length", T_INTEGER, C_OUTPUT, V_DISCRETE, I_CALCULATED, I_Y_LENGTH, 0, NULL, -INFINITY, INFINITY, NULL,
     "bytes of u_string", NO_STATE, "3"},
    {"y_code", T_INTEGER, C_OUTPUT, V_DISCRETE, I_CALCULATED, I_Y_CODE, 0, NULL, -INFINITY, INFINITY, NULL,
     "sum of (i + 1) byte_i of u_string, modulo 1000003", NO_STATE, "3"},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y, 0.0, NULL, -INFINITY, INFINITY, NULL, "u", NO_STATE,
     "5"},
};

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    (void)x;
    int *n = model_integers(inst);
    double *r = model_reals(inst);
    const char *u = model_string(inst, S_U), *suffix = model_string(inst, S_SUFFIX);
    const size_t length = strlen(u), step = strlen(suffix);
    char text[STRING_CAPACITY];
    size_t used = length; /* u fits: it is a slot of the same capacity */
    unsigned long code = 0;

    for (size_t i = 0; i < length; i++) code = (code + (i + 1) * (unsigned char)u[i]) % CODE_MODULUS;
    memcpy(text, u, length);
    for (int k = 0; k < n[I_REPEAT] && used < STRING_CAPACITY - 1; k++) {
        size_t take = step < STRING_CAPACITY - 1 - used ? step : STRING_CAPACITY - 1 - used;
        memcpy(text + used, suffix, take);
        used += take;
    }
    text[used] = '\0';
    model_set_string(inst, S_Y, text);
    n[I_Y_LENGTH] = (int)length;
    n[I_Y_CODE] = (int)code;
    r[R_Y] = r[R_U];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "text",
    .guid = "{4f6d2b8e-91c3-4a57-b0de-3e8a7c15f942}",
    .description = "String signals: y_string = u_string + repeat x suffix, its length and checksum (String "
                   "connection tests)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .n_booleans = 0,
    .n_strings = N_STRINGS,
    .n_states = 0,
    .state_slots = NULL,
    .derivative_slots = NULL,
    .initialize = NULL,
    .derivatives = NULL,
    .jacobian = NULL,
    .outputs = outputs,
};
