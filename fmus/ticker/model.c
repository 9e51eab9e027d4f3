/* ticker: an FMI 3.0 Co-Simulation model whose output clock `tick` ticks at its time events
 * t = k period (k = 1, 2, ...); the Int32 output `ticks` counts them: ticks(t) = floor(t / period).
 * No continuous state. An importer in Event Mode reads the clock with fmi3GetClock after the event
 * iteration (fmus/fmi/clocks.c: model_tick).
 */
#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_PERIOD, VR_TICK, VR_TICKS, N_VARIABLES };

enum { R_PERIOD = R_MODEL_START, R_NEXT, N_REALS };
enum { I_TICK = I_MODEL_START, I_TICKS, N_INTEGERS };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"period", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_PERIOD, 1.0, NULL, 0.0, INFINITY, "s",
     "time between two ticks", NO_STATE, NULL},
    {"tick", T_CLOCK, C_OUTPUT, V_DISCRETE, I_DEFAULT, I_TICK, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "output clock, ticking at every time event", NO_STATE, ""},
    {"ticks", T_INTEGER, C_OUTPUT, V_DISCRETE, I_EXACT, I_TICKS, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "the number of ticks so far", NO_STATE, ""},
};

static const ClockDef CLOCKS[] = {{VR_TICK, CLOCK_TRIGGERED, 0.0, 0, -1}};

static ModelStatus initialize(Instance *inst) {
    model_reals(inst)[R_NEXT] = model_reals(inst)[R_PERIOD];
    return MODEL_OK;
}

static ModelStatus update(Instance *inst, double t, double *x, EventUpdate *ev) {
    double *r = model_reals(inst);
    int *ticks = &model_integers(inst)[I_TICKS];
    (void)x;
    if (t >= r[R_NEXT] - 1e-9 * r[R_PERIOD]) { /* the time event (an importer may meet it to rounding) */
        ++*ticks;
        r[R_NEXT] = r[R_PERIOD] * (double)(*ticks + 1); /* from the integer: no drift */
        model_tick(inst, VR_TICK);
        ev->changed = 1;
    }
    ev->next_event_time = r[R_NEXT];
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "ticker",
    .guid = "{3c7e1b52-9a4d-4f08-b6e2-5d1a8c0f7e93}",
    .description = "Ticker: an output clock ticking at time events every period (FMI 3.0 Co-Simulation)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .fmi3_only = 1,
    .clocks = CLOCKS,
    .n_clocks = 1,
    .initialize = initialize,
    .update = update,
};
