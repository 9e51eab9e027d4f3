/* blocks_add3: Modelica.Blocks.Math.Add3, y = k1 u1 + k2 u2 + k3 u3, with the interface of
 * OpenModelica's export of that block (the OMSimulator scenes under tests/ssp/ name it): the same
 * variable names, causalities, variabilities and start values. */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_U1, VR_U2, VR_U3, VR_Y, VR_K1, VR_K2, VR_K3, N_VARIABLES };
enum { R_U1 = R_MODEL_START, R_U2, R_U3, R_Y, R_K1, R_K2, R_K3, N_REALS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"u1", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U1, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Connector of Real input signal 1", NO_STATE, NULL},
    {"u2", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U2, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Connector of Real input signal 2", NO_STATE, NULL},
    {"u3", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U3, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Connector of Real input signal 3", NO_STATE, NULL},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Connector of Real output signal", NO_STATE, "2 3 4"},
    {"k1", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_K1, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "Gain of input signal 1", NO_STATE, NULL},
    {"k2", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_K2, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "Gain of input signal 2", NO_STATE, NULL},
    {"k3", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_K3, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "Gain of input signal 3", NO_STATE, NULL},
};

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    (void)x;
    double *r = model_reals(inst);
    r[R_Y] = r[R_K1] * r[R_U1] + r[R_K2] * r[R_U2] + r[R_K3] * r[R_U3];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "blocks_add3",
    .guid = "{a41f6d93-2c07-4e5b-8b3a-7f1e0d6c9a24}",
    .description = "Output the sum of the three inputs (Modelica.Blocks.Math.Add3)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .outputs = outputs,
};
