/* identity: one input and one output of each FMI 1.0/2.0 type, each output equal to its input
 * (the interface of the ecos/ViProMa identity FMU: realIn -> realOut, integerIn -> integerOut,
 * booleanIn -> booleanOut, stringIn -> stringOut). */
#include "model.h"

enum {
    VR_SOLVER,
    VR_INTERNAL_STEP,
    VR_REAL_IN,
    VR_INTEGER_IN,
    VR_BOOLEAN_IN,
    VR_STRING_IN,
    VR_REAL_OUT,
    VR_INTEGER_OUT,
    VR_BOOLEAN_OUT,
    VR_STRING_OUT,
    N_VARIABLES
};
enum { R_IN = R_MODEL_START, R_OUT, N_REALS };
enum { I_IN = I_MODEL_START, I_OUT, N_INTEGERS };
enum { B_IN, B_OUT, N_BOOLEANS };
enum { S_IN, S_OUT, N_STRINGS };

#define IN(name, type, slot, start, start_string)                                                           \
    {name, type, C_INPUT, V_DISCRETE, I_DEFAULT, slot, start, start_string, -INFINITY, INFINITY, NULL, NULL, \
     NO_STATE, NULL}
#define OUT(name, type, slot, input_vr)                                                                      \
    {name, type, C_OUTPUT, V_DISCRETE, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, NULL, NULL,       \
     NO_STATE, input_vr}

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    IN("realIn", T_REAL, R_IN, 0.0, NULL),
    IN("integerIn", T_INTEGER, I_IN, 0.0, NULL),
    IN("booleanIn", T_BOOLEAN, B_IN, 0.0, NULL),
    IN("stringIn", T_STRING, S_IN, 0.0, ""),
    OUT("realOut", T_REAL, R_OUT, "2"),
    OUT("integerOut", T_INTEGER, I_OUT, "3"),
    OUT("booleanOut", T_BOOLEAN, B_OUT, "4"),
    OUT("stringOut", T_STRING, S_OUT, "5"),
};

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    (void)x;
    model_reals(inst)[R_OUT] = model_reals(inst)[R_IN];
    model_integers(inst)[I_OUT] = model_integers(inst)[I_IN];
    model_booleans(inst)[B_OUT] = model_booleans(inst)[B_IN];
    model_set_string(inst, S_OUT, model_string(inst, S_IN));
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "identity",
    .guid = "{5b0e3c1a-8f27-4d6e-a9c4-2e71d0b6f853}",
    .description = "each output equals its input (Real, Integer, Boolean, String)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .n_booleans = N_BOOLEANS,
    .n_strings = N_STRINGS,
    .n_states = 0,
    .state_slots = NULL,
    .derivative_slots = NULL,
    .initialize = NULL,
    .derivatives = NULL,
    .jacobian = NULL,
    .outputs = outputs,
};
