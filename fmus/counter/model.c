/* counter: an FMI 3.0 Co-Simulation model with a triggered input clock `inClock`, which the importer
 * sets in Event Mode (fmi3SetClock); the Int32 output `count` counts its ticks. No continuous state.
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_IN_CLOCK, VR_COUNT, N_VARIABLES };

enum { N_REALS = R_MODEL_START };
enum { I_IN_CLOCK = I_MODEL_START, I_COUNT, N_INTEGERS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"inClock", T_CLOCK, C_INPUT, V_DISCRETE, I_DEFAULT, I_IN_CLOCK, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "input clock, triggered by the importer", NO_STATE, NULL},
    {"count", T_INTEGER, C_OUTPUT, V_DISCRETE, I_EXACT, I_COUNT, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "the ticks of inClock so far", NO_STATE, ""},
};

static const ClockDef CLOCKS[] = {{VR_IN_CLOCK, CLOCK_TRIGGERED, 0.0, 0, -1}};

static ModelStatus update(Instance *inst, double t, double *x, EventUpdate *ev) {
    int *i = model_integers(inst);
    (void)t, (void)x;
    if (i[I_IN_CLOCK]) { /* set active in this event iteration (fmi3SetClock): one tick */
        i[I_IN_CLOCK] = 0;
        i[I_COUNT]++;
        ev->changed = 1;
    }
    ev->next_event_time = INFINITY;
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "counter",
    .guid = "{b41d9e07-6c2a-4e85-a3f1-0d7c5e2b9f18}",
    .description = "Counter: the ticks of a triggered input clock (FMI 3.0 Co-Simulation in Event Mode)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .fmi3_only = 1,
    .clocks = CLOCKS,
    .n_clocks = 1,
    .update = update,
};
