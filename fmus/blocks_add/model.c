/* blocks_add: Modelica.Blocks.Math.Add, y = k1 u1 + k2 u2, with the interface of OpenModelica's
 * export of that block (the OMSimulator scenes under tests/ssp/ name it): the same variable names,
 * causalities, variabilities, start values and DefaultExperiment stepSize. */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_U1, VR_U2, VR_Y, VR_K1, VR_K2, N_VARIABLES };
enum { R_U1 = R_MODEL_START, R_U2, R_Y, R_K1, R_K2, N_REALS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"u1", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U1, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Connector of Real input signal 1", NO_STATE, NULL},
    {"u2", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U2, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Connector of Real input signal 2", NO_STATE, NULL},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Connector of Real output signal", NO_STATE, "2 3"},
    {"k1", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_K1, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "Gain of input signal 1", NO_STATE, NULL},
    {"k2", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_K2, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "Gain of input signal 2", NO_STATE, NULL},
};

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    (void)x;
    double *r = model_reals(inst);
    r[R_Y] = r[R_K1] * r[R_U1] + r[R_K2] * r[R_U2];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "blocks_add",
    .guid = "{5b0e7c1a-3d84-4f29-a6e1-90c2b7d45e18}",
    .description = "Output the sum of the two inputs (Modelica.Blocks.Math.Add)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .default_step_size = 0.002,
    .outputs = outputs,
};
