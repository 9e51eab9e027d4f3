/* instance.c: block layout, start values, settability rules, output refresh. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "instance.h"

#define ALIGN8(n) (((n) + 7u) & ~(size_t)7u)

double *model_reals(Instance *inst) { return inst->reals; }
int *model_integers(Instance *inst) { return inst->integers; }
int *model_booleans(Instance *inst) { return inst->booleans; }
const char *model_string(Instance *inst, int slot) { return inst->strings + (size_t)slot * STRING_CAPACITY; }

/* Carve the block into its parts; every part starts 8-byte aligned. */
static size_t layout(Instance *inst, unsigned char *base) {
    const ModelDef *m = inst->model;
    size_t off = 0;
#define PART(ptr, type, count)                                        \
    do {                                                              \
        if (base) inst->ptr = (type *)(void *)(base + off);           \
        off = ALIGN8(off + sizeof(type) * (size_t)(count));           \
    } while (0)
    PART(core, Core, 1);
    PART(reals, double, m->n_reals);
    PART(memory, double, solver_memory_size(m->n_states));
    PART(input_derivs, double, inst->n_real_inputs * MAX_INPUT_ORDER);
    PART(integers, int, m->n_integers);
    PART(booleans, int, m->n_booleans);
    PART(strings, char, (size_t)m->n_strings * STRING_CAPACITY);
#undef PART
    return off;
}

Instance *instance_new(const char *name, fmi2Type type, fmi2CallbackLogger logger, fmi2ComponentEnvironment env,
                       int logging_on) {
    const ModelDef *m = &MODEL;
    int n = m->n_states, nv = m->n_variables;
    Instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    inst->model = m;
    inst->type = type;
    inst->logger = logger;
    inst->env = env;
    inst->log_mask = logging_on ? (1u << LOG_N_CATEGORIES) - 1u : 0u;
    inst->name = malloc(strlen(name) + 1);
    inst->real_input_slot = calloc((size_t)nv + 1, sizeof(int));
    inst->input_index = calloc((size_t)nv + 1, sizeof(int));
    inst->checked_vr = calloc((size_t)nv + 1, sizeof(int));
    if (!inst->name || !inst->real_input_slot || !inst->input_index || !inst->checked_vr) goto fail;
    strcpy(inst->name, name);
    for (int vr = 0; vr < nv; vr++) {
        const Variable *v = &m->variables[vr];
        int is_state = 0;
        inst->input_index[vr] = -1;
        if (v->type != T_REAL) continue;
        if (v->causality == C_INPUT) {
            inst->input_index[vr] = inst->n_real_inputs;
            inst->real_input_slot[inst->n_real_inputs++] = v->slot;
        }
        for (int i = 0; i < n; i++) is_state |= m->state_slots[i] == v->slot;
        if (is_state || v->causality == C_OUTPUT) inst->checked_vr[inst->n_checked++] = vr;
    }
    inst->block_size = layout(inst, NULL);
    inst->block = calloc(1, inst->block_size);
    inst->work = solver_work_new(n);
    inst->x = calloc((size_t)n + 1, sizeof(double));
    inst->dx = calloc((size_t)n + 1, sizeof(double));
    inst->input_values = calloc((size_t)inst->n_real_inputs + 1, sizeof(double));
    inst->jac = calloc((size_t)n * (size_t)n + 1, sizeof(double));
    inst->saved_reals = calloc((size_t)m->n_reals + 1, sizeof(double));
    inst->fd_seed_base = calloc((size_t)nv + 1, sizeof(double));
    inst->fd_plus = calloc((size_t)nv + 1, sizeof(double));
    inst->fd_minus = calloc((size_t)nv + 1, sizeof(double));
    if (!inst->block || (n > 0 && !inst->work) || !inst->x || !inst->dx || !inst->input_values || !inst->jac ||
        !inst->saved_reals || !inst->fd_seed_base || !inst->fd_plus || !inst->fd_minus)
        goto fail;
    layout(inst, inst->block);
    instance_reset(inst);
    return inst;
fail:
    instance_free(inst);
    return NULL;
}

void instance_free(Instance *inst) {
    if (!inst) return;
    if (inst->work) solver_work_free(inst->work);
    free(inst->block);
    free(inst->name);
    free(inst->real_input_slot);
    free(inst->input_index);
    free(inst->checked_vr);
    free(inst->x);
    free(inst->dx);
    free(inst->input_values);
    free(inst->jac);
    free(inst->saved_reals);
    free(inst->fd_seed_base);
    free(inst->fd_plus);
    free(inst->fd_minus);
    free(inst);
}

void instance_reset(Instance *inst) {
    const ModelDef *m = inst->model;
    memset(inst->block, 0, inst->block_size);
    for (int vr = 0; vr < m->n_variables; vr++) {
        const Variable *v = &m->variables[vr];
        double start = effective_initial(v) == I_CALCULATED ? 0.0 : v->start;
        switch (v->type) {
        case T_REAL: inst->reals[v->slot] = start; break;
        case T_INTEGER:
        case T_SOLVER: inst->integers[v->slot] = (int)start; break;
        case T_BOOLEAN: inst->booleans[v->slot] = start != 0.0; break;
        case T_STRING: {
            char *s = inst->strings + (size_t)v->slot * STRING_CAPACITY;
            strncpy(s, v->start_string ? v->start_string : "", STRING_CAPACITY - 1);
            s[STRING_CAPACITY - 1] = '\0';
            break;
        }
        }
    }
    solver_reset(inst->memory, m->n_states);
    inst->core->state = ST_INSTANTIATED;
    mark_dirty(inst);
}

const Variable *variable_of(const Instance *inst, fmi2ValueReference vr) {
    if (vr >= (fmi2ValueReference)inst->model->n_variables) return NULL;
    return &inst->model->variables[vr];
}

/* FMI 2.0 default of `initial` from causality and variability. */
Initial effective_initial(const Variable *v) {
    if (v->initial != I_DEFAULT) return v->initial;
    switch (v->causality) {
    case C_PARAMETER: return I_EXACT;
    case C_CALCULATED_PARAMETER: return I_CALCULATED;
    case C_INPUT:
    case C_INDEPENDENT: return I_DEFAULT; /* no initial attribute */
    case C_OUTPUT:
    case C_LOCAL: return v->variability == V_CONSTANT ? I_EXACT : I_CALCULATED;
    }
    return I_DEFAULT;
}

/* FMI 2.0 rules for fmi2SetXXX per state (section 3.2.3 / 4.2.4 of the standard). */
const char *not_settable_reason(const Instance *inst, const Variable *v) {
    Initial init = effective_initial(v);
    if (v->variability == V_CONSTANT) return "it is a constant";
    if (v->causality == C_INDEPENDENT) return "it is the independent variable";
    if (v->causality == C_CALCULATED_PARAMETER) return "it is a calculated parameter";
    switch (inst->core->state) {
    case ST_INSTANTIATED:
        if (v->causality == C_INPUT || init == I_EXACT || init == I_APPROX) return NULL;
        return "it has no start value (initial=\"calculated\")";
    case ST_INITIALIZATION:
        if (v->causality == C_INPUT || init == I_EXACT) return NULL;
        return "only inputs and variables with initial=\"exact\" may be set in InitializationMode";
    case ST_STEP_COMPLETE:
    case ST_EVENT:
        if (v->causality == C_INPUT) return NULL;
        if (v->causality == C_PARAMETER && v->variability == V_TUNABLE) return NULL;
        return "only inputs and tunable parameters may be set after initialization";
    case ST_CONTINUOUS_TIME:
        if (v->causality == C_INPUT && v->variability == V_CONTINUOUS) return NULL;
        return "only continuous inputs may be set in ContinuousTimeMode";
    default: return "no variable may be set in this state";
    }
}

void gather_states(Instance *inst, double *x) {
    for (int i = 0; i < inst->model->n_states; i++) x[i] = inst->reals[inst->model->state_slots[i]];
}

void scatter_states(Instance *inst, const double *x) {
    for (int i = 0; i < inst->model->n_states; i++) inst->reals[inst->model->state_slots[i]] = x[i];
}

void mark_dirty(Instance *inst) {
    inst->core->outputs_dirty = 1;
    inst->core->derivatives_dirty = 1;
}

void note_set(Instance *inst, const fmi2ValueReference vr[], size_t nvr) {
    mark_dirty(inst);
    if (inst->core->state != ST_INITIALIZATION) return;
    for (size_t i = 0; i < nvr; i++)
        if (inst->model->variables[vr[i]].causality != C_INPUT) inst->core->initialized = 0;
}

int run_initialize(Instance *inst, const char *function) {
    const ModelDef *m = inst->model;
    if (inst->core->initialized) return 0;
    if (m->initialize && m->initialize(inst) != MODEL_OK) {
        layer_log(inst, LOG_ERROR, "%s: model initialization failed%s", function, model_error_suffix(inst));
        return 1;
    }
    inst->core->initialized = 1;
    return 0;
}

int eval_outputs(Instance *inst) {
    const ModelDef *m = inst->model;
    if (!m->outputs) return 0;
    gather_states(inst, inst->x);
    return m->outputs(inst, inst->core->time, inst->x) != MODEL_OK;
}

int eval_derivatives(Instance *inst) {
    const ModelDef *m = inst->model;
    if (m->n_states == 0) return 0;
    gather_states(inst, inst->x);
    if (m->derivatives(inst, inst->core->time, inst->x, inst->dx) != MODEL_OK) return 1;
    for (int i = 0; i < m->n_states; i++) inst->reals[m->derivative_slots[i]] = inst->dx[i];
    return 0;
}

int refresh(Instance *inst, int derivatives, const char *function) {
    Core *c = inst->core;
    if (c->state == ST_ERROR) return 0; /* values stay as the failure left them, for inspection */
    if (c->state == ST_INITIALIZATION && (c->outputs_dirty || (derivatives && c->derivatives_dirty)) &&
        run_initialize(inst, function))
        return 1;
    if (c->outputs_dirty) {
        if (eval_outputs(inst)) {
            layer_log(inst, LOG_ERROR, "%s: model outputs failed at t = %.17g%s", function, c->time,
                      model_error_suffix(inst));
            return 1;
        }
        c->outputs_dirty = 0;
    }
    if (derivatives && c->derivatives_dirty) {
        if (eval_derivatives(inst)) {
            layer_log(inst, LOG_ERROR, "%s: model derivatives failed at t = %.17g%s", function, c->time,
                      model_error_suffix(inst));
            return 1;
        }
        c->derivatives_dirty = 0;
    }
    return 0;
}

int check_finite(Instance *inst, const char *function) {
    for (int k = 0; k < inst->n_checked; k++) {
        const Variable *v = &inst->model->variables[inst->checked_vr[k]];
        if (!isfinite(inst->reals[v->slot])) {
            layer_log(inst, LOG_ERROR, "%s: %s %s = %g at t = %.17g", function,
                      v->causality == C_OUTPUT ? "output" : "state", v->name, inst->reals[v->slot],
                      inst->core->time);
            return 1;
        }
    }
    return 0;
}
