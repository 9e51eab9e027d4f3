/* clocks: FMI 3.0 Scheduled Execution, the interface and behaviour of the Reference FMUs' Clocks model
 * (modelica/Reference-FMUs, Clocks/): three input clocks whose partitions count their ticks, an output
 * clock, an Int32 input summed at the ticks of inClock2.
 *
 *   inClock1  constant, every 1 s, priority 0: inClock1Ticks and totalInClockTicks + 1; at t = 4 it
 *             counts inClock3 down by 0 s (inClock3 then ticks at the same time)
 *   inClock2  triggered by the importer, priority 1: inClock2Ticks and totalInClockTicks + 1,
 *             result2 += input2, input2 = 0
 *   inClock3  countdown, priority 2: inClock3Ticks and totalInClockTicks + 1, output3 = 1000
 *   outClock  ticks after a partition that makes totalInClockTicks a multiple of 5 (unless it ticked
 *             unread in the same activation round)
 * (The original's third partition also burns CPU time; this one does not.)
 */
#include "model.h"

enum {
    VR_IN_CLOCK1, VR_IN_CLOCK2, VR_IN_CLOCK3, VR_OUT_CLOCK,
    VR_IN_CLOCK1_TICKS, VR_IN_CLOCK2_TICKS, VR_IN_CLOCK3_TICKS, VR_TOTAL, VR_RESULT2, VR_INPUT2, VR_OUTPUT3,
    N_VARIABLES
};
enum { R_INTERVAL3 = R_MODEL_START, N_REALS };
enum {
    I_IN_CLOCK1 = I_MODEL_START, I_IN_CLOCK2, I_IN_CLOCK3, I_OUT_CLOCK,
    I_IN_CLOCK1_TICKS, I_IN_CLOCK2_TICKS, I_IN_CLOCK3_TICKS, I_TOTAL, I_RESULT2, I_INPUT2, I_OUTPUT3,
    N_INTEGERS
};

#define CLOCK(name, causality, slot, description, deps) \
    {name, T_CLOCK, causality, V_DISCRETE, I_DEFAULT, slot, 0.0, NULL, -INFINITY, INFINITY, NULL, description, NO_STATE, deps}
#define COUNTER(name, causality, slot, description, deps) \
    {name, T_INT32, causality, V_DISCRETE, I_DEFAULT, slot, 0.0, NULL, -INFINITY, INFINITY, NULL, description, NO_STATE, deps}

static const Variable VARIABLES[N_VARIABLES] = {
    CLOCK("inClock1", C_INPUT, I_IN_CLOCK1, "periodic input clock, every second", NULL),
    CLOCK("inClock2", C_INPUT, I_IN_CLOCK2, "input clock triggered by the importer", NULL),
    CLOCK("inClock3", C_INPUT, I_IN_CLOCK3, "countdown input clock, counted down by inClock1's partition", NULL),
    CLOCK("outClock", C_OUTPUT, I_OUT_CLOCK, "ticks when totalInClockTicks becomes a multiple of 5", "0 1 2"),
    COUNTER("inClock1Ticks", C_OUTPUT, I_IN_CLOCK1_TICKS, "ticks of inClock1", "0"),
    COUNTER("inClock2Ticks", C_OUTPUT, I_IN_CLOCK2_TICKS, "ticks of inClock2", "1"),
    COUNTER("inClock3Ticks", C_OUTPUT, I_IN_CLOCK3_TICKS, "ticks of inClock3", "2"),
    COUNTER("totalInClockTicks", C_OUTPUT, I_TOTAL, "ticks of all input clocks", "0 1 2"),
    COUNTER("result2", C_OUTPUT, I_RESULT2, "sum of input2 at the ticks of inClock2", "1 9"),
    COUNTER("input2", C_INPUT, I_INPUT2, "added to result2 at the next tick of inClock2", NULL),
    COUNTER("output3", C_OUTPUT, I_OUTPUT3, "1000 once inClock3 ticked", "2"),
};

/* the `clocks` attribute of each variable: the clocks that activate it */
static const char *const CLOCKED[N_VARIABLES] = {
    [VR_IN_CLOCK3] = "0", [VR_OUT_CLOCK] = "0 1 2", [VR_IN_CLOCK1_TICKS] = "0", [VR_IN_CLOCK2_TICKS] = "1",
    [VR_TOTAL] = "0 1 2", [VR_RESULT2] = "1",       [VR_OUTPUT3] = "2",
};

static const ClockDef CLOCKS[] = {
    {VR_IN_CLOCK1, CLOCK_CONSTANT, 1.0, 0, -1},
    {VR_IN_CLOCK2, CLOCK_TRIGGERED, 0.0, 1, -1},
    {VR_IN_CLOCK3, CLOCK_COUNTDOWN, 0.0, 2, R_INTERVAL3},
    {VR_OUT_CLOCK, CLOCK_TRIGGERED, 0.0, 0, -1},
};

/* One more input tick: outClock ticks where the total becomes a multiple of 5, unless it ticked unread. */
static void count(Instance *inst) {
    int *i = model_integers(inst);
    i[I_TOTAL]++;
    i[I_OUT_CLOCK] = !i[I_OUT_CLOCK] && i[I_TOTAL] % 5 == 0;
    if (i[I_OUT_CLOCK]) model_tick(inst, VR_OUT_CLOCK);
}

static ModelStatus activate(Instance *inst, int clock_vr, double t) {
    int *i = model_integers(inst);
    switch (clock_vr) {
    case VR_IN_CLOCK1:
        i[I_IN_CLOCK1_TICKS]++;
        if ((int)t == 4) model_count_down(inst, VR_IN_CLOCK3, 0.0);
        break;
    case VR_IN_CLOCK2:
        i[I_IN_CLOCK2_TICKS]++;
        i[I_RESULT2] += i[I_INPUT2];
        i[I_INPUT2] = 0;
        break;
    case VR_IN_CLOCK3:
        i[I_IN_CLOCK3_TICKS]++;
        i[I_OUTPUT3] = 1000;
        break;
    default: return MODEL_ERROR;
    }
    count(inst);
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "clocks",
    .guid = "{5d2f0a3e-8c41-4b6e-9a77-1e0c3b9d2f64}",
    .description = "Clocks: Scheduled Execution with periodic, triggered, countdown and output clocks",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .fmi3_only = 1,
    .default_step_size = 1.0,
    .clocks = CLOCKS,
    .n_clocks = sizeof CLOCKS / sizeof CLOCKS[0],
    .clocked = CLOCKED,
    .activate = activate,
};
