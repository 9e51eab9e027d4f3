/* clocks.c: FMI 3.0 Scheduled Execution of a model with clocks (model.h: ModelDef.clocks).
 *
 * The importer activates the partition of an input clock at a time (fmi3ActivateModelPartition:
 * ModelDef.activate); the partition may tick output clocks (model_tick) and count input clocks down
 * (model_count_down), and each time the layer tells the importer through its clockUpdate callback.
 * A Clock variable's state is an integer slot (T_CLOCK), so FMU state copies hold it: an output
 * clock's tick until fmi3GetClock reads it, a countdown clock's interval qualifier until
 * fmi3GetIntervalDecimal reads it (its interval in a real slot). The Clock Activation Mode of
 * Scheduled Execution is the layer's Step Mode: inputs are set and outputs read there. Partitions
 * run one after the other in the caller's thread (no preemption). A Co-Simulation model without
 * partitions (no ModelDef.activate) may tick output clocks at its events (model_tick in its update),
 * which the importer reads with fmi3GetClock in Event Mode or after it, and have triggered input
 * clocks, which the importer sets in Event Mode (fmi3SetClock) before fmi3UpdateDiscreteStates:
 * its update reads and clears their slots.
 */
#include "instance.h"

enum { QUALIFIER_NOT_YET_KNOWN = 0, QUALIFIER_UNCHANGED = 1, QUALIFIER_CHANGED = 2 }; /* fmi3IntervalQualifier */

static const ClockDef *clock_def(const Instance *inst, unsigned vr) {
    for (int k = 0; k < inst->model->n_clocks; k++)
        if ((unsigned)inst->model->clocks[k].vr == vr) return &inst->model->clocks[k];
    return NULL;
}

/* The clock of value reference vr with the causality asked for (C_INPUT, C_OUTPUT; -1 either), or
 * NULL after logging why not. */
static const ClockDef *clock_of(Instance *inst, const char *function, unsigned vr, int causality) {
    const Variable *v = variable_of(inst, vr);
    const ClockDef *c = clock_def(inst, vr);
    if (!v || v->type != T_CLOCK || !c) {
        layer_log(inst, LOG_ERROR, "%s: value reference %u is not a Clock", function, vr);
        return NULL;
    }
    if (causality >= 0 && (int)v->causality != causality) {
        layer_log(inst, LOG_ERROR, "%s: Clock \"%s\" is not an %s clock", function, v->name,
                  causality == C_INPUT ? "input" : "output");
        return NULL;
    }
    return c;
}

static void clock_update(Instance *inst) {
    if (inst->clock_update) inst->clock_update(inst->env);
}

void model_tick(Instance *inst, int clock_vr) {
    const Variable *v = variable_of(inst, (unsigned)clock_vr);
    if (v && v->type == T_CLOCK) inst->integers[v->slot] = 1;
    clock_update(inst);
}

void model_count_down(Instance *inst, int clock_vr, double interval) {
    const Variable *v = variable_of(inst, (unsigned)clock_vr);
    const ClockDef *c = clock_def(inst, (unsigned)clock_vr);
    if (!v || !c || c->interval_slot < 0) return;
    inst->reals[c->interval_slot] = interval;
    inst->integers[v->slot] = QUALIFIER_CHANGED;
    clock_update(inst);
}

LayerStatus clock_activate(Instance *inst, const char *function, unsigned vr, double t) {
    if (!inst->scheduled || !inst->model->activate) {
        layer_log(inst, LOG_ERROR, "%s: not instantiated for Scheduled Execution", function);
        return LAYER_ERROR;
    }
    if (!check_state(inst, function, S_STEP) || !clock_of(inst, function, vr, C_INPUT)) return LAYER_ERROR;
    inst->core->time = t;
    ModelStatus st = inst->model->activate(inst, (int)vr, t);
    if (st == MODEL_OK) return LAYER_OK;
    layer_log(inst, LOG_ERROR, "%s: the partition of \"%s\" failed at t = %g%s", function,
              variable_of(inst, vr)->name, t, model_error_suffix(inst));
    if (st == MODEL_FATAL) return LAYER_FATAL;
    inst->core->state = ST_ERROR;
    return LAYER_ERROR;
}

LayerStatus clock_get(Instance *inst, const char *function, const unsigned vr[], size_t nvr, int ticked[]) {
    if (!check_state(inst, function, S_STEP | S_EVENT)) return LAYER_ERROR; /* Co-Simulation: after its events */
    for (size_t i = 0; i < nvr; i++)
        if (!clock_of(inst, function, vr[i], C_OUTPUT)) return LAYER_ERROR;
    for (size_t i = 0; i < nvr; i++) {
        int *slot = &inst->integers[variable_of(inst, vr[i])->slot];
        ticked[i] = *slot != 0;
        *slot = 0;
    }
    return LAYER_OK;
}

LayerStatus clock_set(Instance *inst, const char *function, const unsigned vr[], size_t nvr, const int active[]) {
    if (!check_state(inst, function, S_EVENT)) return LAYER_ERROR; /* an input clock ticks in Event Mode */
    for (size_t i = 0; i < nvr; i++)
        if (!clock_of(inst, function, vr[i], C_INPUT)) return LAYER_ERROR;
    for (size_t i = 0; i < nvr; i++) inst->integers[variable_of(inst, vr[i])->slot] = active[i] != 0;
    return LAYER_OK;
}

LayerStatus clock_intervals(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                            double intervals[], int qualifiers[]) {
    if (!check_state(inst, function, S_STEP)) return LAYER_ERROR;
    for (size_t i = 0; i < nvr; i++)
        if (!clock_of(inst, function, vr[i], -1)) return LAYER_ERROR;
    for (size_t i = 0; i < nvr; i++) {
        const ClockDef *c = clock_def(inst, vr[i]);
        int *slot = &inst->integers[variable_of(inst, vr[i])->slot];
        switch (c->variability) {
        case CLOCK_CONSTANT:
        case CLOCK_FIXED:
        case CLOCK_TUNABLE: /* as declared: the layer has no fmi3SetInterval* */
            intervals[i] = c->interval;
            qualifiers[i] = QUALIFIER_UNCHANGED;
            break;
        case CLOCK_COUNTDOWN:
            qualifiers[i] = *slot;
            intervals[i] = *slot == QUALIFIER_CHANGED ? inst->reals[c->interval_slot] : 0.0;
            if (*slot == QUALIFIER_CHANGED) *slot = QUALIFIER_UNCHANGED;
            break;
        default:
            intervals[i] = 0.0;
            qualifiers[i] = QUALIFIER_NOT_YET_KNOWN;
        }
    }
    return LAYER_OK;
}
