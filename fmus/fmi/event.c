/* event.c: a model's events through the layer (ModelDef.event_indicators, update): the Model
 * Exchange functions and doStep's events call these. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "instance.h"

#define MAX_EVENT_ROUNDS 100 /* an event iteration that goes on longer is the model's error */

int model_has_events(const ModelDef *m) { return m->n_event_indicators > 0 || m->update || m->step_event; }

int event_update(Instance *inst, const char *function, int *needed, int *states_changed, int *terminate) {
    const ModelDef *m = inst->model;
    Core *c = inst->core;
    EventUpdate ev = {0, INFINITY};
    *needed = *states_changed = *terminate = 0;
    if (!m->update) {
        c->next_event_time = INFINITY;
        return 0;
    }
    gather_states(inst, inst->x);
    memcpy(inst->saved_reals, inst->reals, sizeof(double) * (size_t)m->n_reals);
    ModelStatus st = m->update(inst, c->time, inst->x, &ev);
    if (st == MODEL_ERROR || st == MODEL_FATAL) {
        if (st == MODEL_FATAL) c->fatal = 1;
        layer_log(inst, LOG_ERROR, "%s: the model's event update failed at t = %.17g s%s", function, c->time,
                  model_error_suffix(inst));
        return 1;
    }
    for (int i = 0; i < m->n_states; i++) *states_changed |= inst->x[i] != inst->saved_reals[m->state_slots[i]];
    if (*states_changed) scatter_states(inst, inst->x);
    *needed = ev.changed != 0;
    *terminate = st == MODEL_TERMINATE;
    c->next_event_time = ev.next_event_time;
    if (ev.changed || *states_changed) { /* discrete variables may have changed: f's kept value is stale */
        mark_dirty(inst);
        forget_rhs(inst);
    }
    return 0;
}

int event_iteration(Instance *inst, const char *function, int *states_changed, int *terminate) {
    int needed, changed;
    *states_changed = *terminate = 0;
    for (int round = 0; round < MAX_EVENT_ROUNDS; round++) {
        if (event_update(inst, function, &needed, &changed, terminate)) return 1;
        *states_changed |= changed;
        if (!needed || *terminate) return 0;
    }
    /* the caller reports the failure, with this as the model's error */
    snprintf(inst->model_error, sizeof inst->model_error,
             ": the event iteration at t = %.17g s does not end (%d rounds)", inst->core->time, MAX_EVENT_ROUNDS);
    return 1;
}

int event_indicators_now(Instance *inst, double *z) {
    const ModelDef *m = inst->model;
    if (m->n_event_indicators == 0) return 0;
    gather_states(inst, inst->x);
    ModelStatus st = m->event_indicators(inst, inst->core->time, inst->x, z);
    if (st == MODEL_FATAL) inst->core->fatal = 1;
    return st != MODEL_OK;
}
