/* blocks_gain: Modelica.Blocks.Math.Gain, y = k u, with the interface of OpenModelica's export of
 * that block (the OMSimulator scenes under tests/ssp/ name it): the same variable names,
 * causalities, variabilities, start values, unit and DefaultExperiment stepSize. */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_U, VR_Y, VR_K, N_VARIABLES };
enum { R_U = R_MODEL_START, R_Y, R_K, N_REALS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Input signal connector", NO_STATE, NULL},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, R_Y, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "Output signal connector", NO_STATE, "2"},
    {"k", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_K, 1.0, NULL, -INFINITY, INFINITY, "1",
     "Gain value multiplied with input signal", NO_STATE, NULL},
};

static ModelStatus outputs(Instance *inst, double t, const double *x) {
    (void)t;
    (void)x;
    double *r = model_reals(inst);
    r[R_Y] = r[R_K] * r[R_U];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "blocks_gain",
    .guid = "{e8c2a5f0-6b19-4d73-9e4c-1a3f7b20d856}",
    .description = "Output the product of a gain value with the input signal (Modelica.Blocks.Math.Gain)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .default_step_size = 0.002,
    .outputs = outputs,
};
