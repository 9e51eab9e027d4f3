/* oms_stimuli: the stimuli of OMSimulator's DC-motor scene (component stimuli_model of
 * tests/ssp/OpenModelica-OMSimulator/dcmotor) with the interface the scene gives it: the voltage
 * U and the load torque M_load out, the parameters of a voltage step and a constant load.  The
 * original (an OpenModelica export, Model Exchange only) is not kept; these are our equations,
 * those of Modelica.Blocks.Sources.Step and Constant:
 *
 *   U = offset + (t < startTime ? 0 : height),   M_load = MLoad.k
 *
 * No state and no events: a step after the start time shows from the first time at or after it
 * that the model is evaluated. */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_OFFSET, VR_START_TIME, VR_HEIGHT, VR_LOAD, VR_U, VR_M_LOAD, N_VARIABLES };
enum { R_OFFSET = R_MODEL_START, R_START_TIME, R_HEIGHT, R_LOAD, R_U, R_M_LOAD, N_REALS };

#define PARAMETER(name, slot, start, unit, description) \
    {name, T_REAL, C_PARAMETER, V_FIXED, I_EXACT, slot, start, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, NULL}
#define OUTPUT(name, slot, unit, description) \
    {name, T_REAL, C_OUTPUT, V_CONTINUOUS, I_CALCULATED, slot, 0.0, NULL, -INFINITY, INFINITY, unit, description, NO_STATE, ""}

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_RK4, 0.0),
    PARAMETER("Voltage_step.offset", R_OFFSET, 0.0, NULL, "Offset of output signal y"),
    PARAMETER("Voltage_step.startTime", R_START_TIME, 0.0, "s", "Output y = offset for time < startTime"),
    PARAMETER("Voltage_step.height", R_HEIGHT, 12.0, "V", "Height of step"),
    PARAMETER("MLoad.k", R_LOAD, -0.5, "N.m", "Constant output value"),
    OUTPUT("U", R_U, "V", "voltage: the step"),
    OUTPUT("M_load", R_M_LOAD, "N.m", "load torque: MLoad.k"),
};

static ModelStatus outputs(Instance *inst, double t, const double *x)
{
    double *r = model_reals(inst);
    (void)x;
    r[R_U] = r[R_OFFSET] + (t < r[R_START_TIME] ? 0.0 : r[R_HEIGHT]);
    r[R_M_LOAD] = r[R_LOAD];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "oms_stimuli",
    .guid = "{10d5f266-511b-417e-9297-5f86c8daf14d}",
    .description = "stimuli of the DC-Motor scene: a voltage step and a constant load torque",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = I_MODEL_START,
    .me_only = 1,
    .default_step_size = 0.002,
    .outputs = outputs,
};
