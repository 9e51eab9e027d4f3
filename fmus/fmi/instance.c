/* instance.c: block layout, start values, settability rules, get/set checks, output refresh,
 * the state machine's transitions and FMU state copies, for every FMI interface of the layer. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "instance.h"

#define ALIGN8(n) (((n) + 7u) & ~(size_t)7u)

double *model_reals(Instance *inst) { return inst->reals; }
int *model_integers(Instance *inst) { return inst->integers; }
int *model_booleans(Instance *inst) { return inst->booleans; }
int64_t *model_int64s(Instance *inst) { return inst->int64s; }
uint64_t *model_uint64s(Instance *inst) { return inst->uint64s; }
double model_time(Instance *inst) { return inst->core->time; }
const char *model_string(Instance *inst, int slot) { return inst->strings + (size_t)slot * STRING_CAPACITY; }

int model_set_string(Instance *inst, int slot, const char *value) {
    char *s = inst->strings + (size_t)slot * STRING_CAPACITY;
    size_t n = value ? strlen(value) : 0;
    int cut = n > STRING_CAPACITY - 1;
    if (cut) n = STRING_CAPACITY - 1;
    if (n) memmove(s, value, n);
    s[n] = '\0';
    return cut;
}

const unsigned char *model_binary(Instance *inst, int slot, size_t *size) {
    const BinarySlot *b = &inst->binaries[slot];
    if (size) *size = (size_t)b->size;
    return b->data;
}

int model_set_binary(Instance *inst, int slot, const void *data, size_t size) {
    BinarySlot *b = &inst->binaries[slot];
    if (size > BINARY_CAPACITY) return 1;
    if (size) memmove(b->data, data, size);
    b->size = size;
    return 0;
}

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
    PART(int64s, int64_t, m->n_int64s);
    PART(uint64s, uint64_t, m->n_uint64s);
    PART(binaries, BinarySlot, m->n_binaries);
#undef PART
    return off;
}

static int is_real_class(int type) { return type == T_REAL || type == T_FLOAT32; }

Instance *instance_new(const char *name, InstanceKind kind, int fmi_version, EmitFn emit, void (*logger)(void),
                       void *env, int logging_on) {
    const ModelDef *m = &MODEL;
    int n = m->n_states, nv = m->n_variables, n_input_elements = 0;
    Instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    inst->model = m;
    inst->kind = kind;
    inst->fmi_version = fmi_version;
    inst->emit = emit;
    inst->logger = logger;
    inst->env = env;
    inst->log_mask = logging_on ? (1u << LOG_N_CATEGORIES) - 1u : 0u;
    inst->name = malloc(strlen(name) + 1);
    for (int vr = 0; vr < nv; vr++)
        if (m->variables[vr].type == T_REAL && m->variables[vr].causality == C_INPUT)
            n_input_elements += (int)variable_size(inst, (unsigned)vr);
    inst->real_input_slot = calloc((size_t)n_input_elements + 1, sizeof(int));
    inst->input_index = calloc((size_t)nv + 1, sizeof(int));
    inst->checked_vr = calloc((size_t)nv + 1, sizeof(int));
    if (!inst->name || !inst->real_input_slot || !inst->input_index || !inst->checked_vr) goto fail;
    strcpy(inst->name, name);
    for (int vr = 0; vr < nv; vr++) {
        const Variable *v = &m->variables[vr];
        int is_state = 0;
        inst->input_index[vr] = -1;
        if (!is_real_class(v->type)) continue;
        if (v->type == T_REAL && v->causality == C_INPUT) {
            size_t size = variable_size(inst, (unsigned)vr);
            inst->input_index[vr] = inst->n_real_inputs;
            for (size_t k = 0; k < size; k++) inst->real_input_slot[inst->n_real_inputs++] = v->slot + (int)k;
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
    inst->rhs_x = calloc((size_t)n + 1, sizeof(double));
    inst->rhs_dx = calloc((size_t)n + 1, sizeof(double));
    inst->rhs_u = calloc((size_t)inst->n_real_inputs + 1, sizeof(double));
    inst->events = event_work_new(n, m->n_event_indicators);
    inst->z = calloc((size_t)m->n_event_indicators + 1, sizeof(double));
    if (!inst->events || !inst->z) goto fail;
    if (!inst->block || (n > 0 && !inst->work) || !inst->x || !inst->dx || !inst->input_values || !inst->jac ||
        !inst->saved_reals || !inst->fd_seed_base || !inst->fd_plus || !inst->fd_minus || !inst->rhs_x ||
        !inst->rhs_dx || !inst->rhs_u)
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
    event_work_free(inst->events);
    free(inst->z);
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
    free(inst->rhs_x);
    free(inst->rhs_dx);
    free(inst->rhs_u);
    free(inst);
}

static int hex_digit(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* The start bytes of a Binary from its hex digits (master/fmubuild.py checks them). */
static void binary_start(BinarySlot *b, const char *hex) {
    size_t n = 0;
    for (const char *p = hex ? hex : ""; p[0] && p[1] && n < BINARY_CAPACITY; p += 2) {
        int hi = hex_digit(p[0]), lo = hex_digit(p[1]);
        if (hi < 0 || lo < 0) break;
        b->data[n++] = (unsigned char)(hi * 16 + lo);
    }
    b->size = n;
}

void instance_reset(Instance *inst) {
    const ModelDef *m = inst->model;
    memset(inst->block, 0, inst->block_size);
    for (int vr = 0; vr < m->n_variables; vr++) {
        const Variable *v = &m->variables[vr];
        double start = effective_initial(v) == I_CALCULATED ? 0.0 : v->start;
        size_t size = variable_size(inst, (unsigned)vr);
        for (size_t k = 0; k < size; k++) {
            size_t s = (size_t)v->slot + k;
            switch (v->type) {
            case T_REAL: inst->reals[s] = start; break;
            case T_FLOAT32: inst->reals[s] = (float)start; break;
            case T_INTEGER:
            case T_SOLVER: inst->integers[s] = (int)start; break;
            case T_CLOCK: inst->integers[s] = 0; break; /* no tick; an interval not yet known */
            case T_BOOLEAN: inst->booleans[s] = start != 0.0; break;
            case T_STRING: model_set_string(inst, (int)s, v->start_string); break;
            case T_INT8:
            case T_UINT8:
            case T_INT16:
            case T_UINT16:
            case T_UINT32:
            case T_INT64: inst->int64s[s] = (int64_t)start; break;
            case T_UINT64: inst->uint64s[s] = (uint64_t)start; break;
            case T_BINARY: binary_start(&inst->binaries[s], v->start_string); break;
            default: break;
            }
        }
    }
    solver_reset(inst->memory, m->n_states);
    inst->core->next_event_time = INFINITY;
    inst->core->events = 0;
    inst->core->state = ST_INSTANTIATED;
    mark_dirty(inst);
    forget_rhs(inst);
}

/* FMI 3.0's independent variable: not in the tables, value reference n_variables. */
static const Variable TIME_VARIABLE = {"time", T_REAL, C_INDEPENDENT, V_CONTINUOUS, I_DEFAULT, -1, 0.0, NULL,
                                       -INFINITY, INFINITY, "s", "simulation time", NO_STATE, NULL};

const Variable *variable_of(const Instance *inst, unsigned vr) {
    if (vr < (unsigned)inst->model->n_variables) return &inst->model->variables[vr];
    if (inst->fmi_version == 3 && vr == (unsigned)inst->model->n_variables) return &TIME_VARIABLE;
    return NULL;
}

size_t variable_size(const Instance *inst, unsigned vr) {
    const ModelDef *m = inst->model;
    size_t size = 1;
    if (!m->dimensions || vr >= (unsigned)m->n_variables) return 1;
    for (int d = 0; d < MAX_DIMENSIONS && m->dimensions[vr][d] > 0; d++) size *= (size_t)m->dimensions[vr][d];
    return size;
}

const char *type_name(const Instance *inst, int type) {
    static const char *const names2[] = {"Real", "Integer", "Boolean", "String", "Enumeration"};
    static const char *const names3[T_COUNT] = {"Float64", "Int32",  "Boolean", "String", "Enumeration",
                                                "Float32", "Int8",   "UInt8",   "Int16",  "UInt16",
                                                "UInt32",  "Int64",  "UInt64",  "Binary",  "Clock"};
    if (type < 0 || type >= T_COUNT) return "unknown";
    if (inst->fmi_version <= 2 && type <= T_SOLVER) return names2[type];
    return names3[type];
}

/* Default of `initial` from causality and variability (the same rule in FMI 2.0 and 3.0). */
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

int intermediate_input(const Variable *v) {
    return v->causality == C_INPUT && v->type == T_REAL && v->variability == V_CONTINUOUS;
}

/* Rules for SetXXX per state (FMI 2.0 section 3.2.3 / 4.2.4; FMI 3.0 Co-Simulation without
 * Event Mode keeps them: Step Mode is StepComplete; inside the intermediate-update callback only
 * the intermediate-update inputs). */
const char *not_settable_reason(const Instance *inst, const Variable *v) {
    Initial init = effective_initial(v);
    if (inst->in_intermediate_update)
        return intermediate_input(v) ? NULL
                                     : "only inputs with intermediateUpdate=\"true\" may be set in Intermediate "
                                       "Update Mode";
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

const Variable *lookup(Instance *inst, const char *function, unsigned vr, unsigned types) {
    const Variable *v = variable_of(inst, vr);
    if (!v) {
        layer_log(inst, LOG_ERROR, "%s: value reference %u out of range (model %s has %d variables)", function,
                  vr, inst->model->identifier, inst->model->n_variables + (inst->fmi_version == 3));
        return NULL;
    }
    if (!(types & TYPE_MASK(v->type))) {
        layer_log(inst, LOG_ERROR, "%s: variable %s (value reference %u) is of type %s", function, v->name, vr,
                  type_name(inst, v->type));
        return NULL;
    }
    return v;
}

static void log_count(Instance *inst, const char *function, size_t n_values, size_t needed) {
    layer_log(inst, LOG_ERROR, "%s: %zu values for variables that have %zu", function, n_values, needed);
}

int check_access(Instance *inst, const char *function, const unsigned vr[], size_t nvr, unsigned types,
                 size_t n_values, int set, double (*value_at)(const void *values, size_t j), const void *values) {
    size_t j = 0;
    for (size_t i = 0; i < nvr; i++) {
        const Variable *v = lookup(inst, function, vr[i], types);
        size_t size;
        const char *why;
        if (!v) return 0;
        size = variable_size(inst, vr[i]);
        if (j + size > n_values) {
            size_t needed = j;
            for (size_t r = i; r < nvr; r++) needed += variable_of(inst, vr[r]) ? variable_size(inst, vr[r]) : 1;
            log_count(inst, function, n_values, needed);
            return 0;
        }
        if (set) {
            why = not_settable_reason(inst, v);
            if (why) {
                layer_log(inst, LOG_ERROR, "%s: variable %s cannot be set in state %s: %s", function, v->name,
                          state_name(inst, inst->core->state), why);
                return 0;
            }
            for (size_t k = 0; value_at && k < size; k++) {
                double x = value_at(values, j + k);
                if (!isfinite(x)) {
                    layer_log(inst, LOG_ERROR, "%s: variable %s: value %g is not finite", function, v->name, x);
                    return 0;
                }
                if (x < v->min || x > v->max) {
                    layer_log(inst, LOG_ERROR, "%s: variable %s: value %.17g outside [%g, %g]", function, v->name,
                              x, v->min, v->max);
                    return 0;
                }
            }
        }
        j += size;
    }
    if (j != n_values) {
        log_count(inst, function, n_values, j);
        return 0;
    }
    return 1;
}

int prepare_get(Instance *inst, const char *function, const unsigned vr[], size_t nvr, unsigned types,
                size_t n_values) {
    int need_derivatives = 0;
    if (!check_access(inst, function, vr, nvr, types, n_values, 0, NULL, NULL)) return 0;
    for (size_t i = 0; i < nvr; i++) need_derivatives |= variable_of(inst, vr[i])->derivative_of != NO_STATE;
    return refresh(inst, need_derivatives, function) == 0;
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

void keep_rhs(Instance *inst, double t, const double *x, const double *dx) {
    const size_t n = (size_t)inst->model->n_states;
    inst->rhs_t = t;
    memcpy(inst->rhs_x, x, n * sizeof(double));
    memcpy(inst->rhs_dx, dx, n * sizeof(double));
    for (int i = 0; i < inst->n_real_inputs; i++) inst->rhs_u[i] = inst->reals[inst->real_input_slot[i]];
    inst->rhs_kept = 1;
}

int kept_rhs(Instance *inst, double t, const double *x, double *dx) {
    const size_t n = (size_t)inst->model->n_states;
    if (!inst->rhs_kept || (!inst->model->autonomous && memcmp(&t, &inst->rhs_t, sizeof t) != 0)) return 0;
    if (memcmp(x, inst->rhs_x, n * sizeof(double)) != 0) return 0;
    for (int i = 0; i < inst->n_real_inputs; i++) /* to the bit: -0.0 is not 0.0 here */
        if (memcmp(&inst->reals[inst->real_input_slot[i]], &inst->rhs_u[i], sizeof(double)) != 0) return 0;
    memcpy(dx, inst->rhs_dx, n * sizeof(double));
    return 1;
}

void forget_rhs(Instance *inst) { inst->rhs_kept = 0; }

void note_set(Instance *inst, const unsigned vr[], size_t nvr) {
    mark_dirty(inst);
    for (size_t i = 0; i < nvr && inst->rhs_kept; i++) { /* a parameter or a discrete input: f changed */
        const Variable *v = &inst->model->variables[vr[i]];
        if (v->causality != C_INPUT || v->type != T_REAL) forget_rhs(inst);
    }
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
    ModelStatus st;
    if (!m->outputs) return 0;
    gather_states(inst, inst->x);
    st = m->outputs(inst, inst->core->time, inst->x);
    if (st == MODEL_TERMINATE) {
        inst->core->terminate = 1;
        return 0;
    }
    if (st == MODEL_OK && m->outputs_give_derivatives && m->n_states) {
        for (int i = 0; i < m->n_states; i++) inst->dx[i] = inst->reals[m->derivative_slots[i]];
        keep_rhs(inst, inst->core->time, inst->x, inst->dx);
    }
    return st != MODEL_OK;
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
    for (int i = 0; i < inst->n_checked; i++) {
        const Variable *v = &inst->model->variables[inst->checked_vr[i]];
        size_t size = variable_size(inst, (unsigned)inst->checked_vr[i]);
        for (size_t k = 0; k < size; k++) {
            double x = inst->reals[(size_t)v->slot + k];
            if (isfinite(x)) continue;
            if (size == 1)
                layer_log(inst, LOG_ERROR, "%s: %s %s = %g at t = %.17g", function,
                          v->causality == C_OUTPUT ? "output" : "state", v->name, x, inst->core->time);
            else
                layer_log(inst, LOG_ERROR, "%s: %s %s element %zu = %g at t = %.17g", function,
                          v->causality == C_OUTPUT ? "output" : "state", v->name, k, x, inst->core->time);
            return 1;
        }
    }
    return 0;
}

/* ----------------------------------------------------------- transitions */

int setup_experiment(Instance *inst, const char *function, double start, int stop_defined, double stop) {
    if (!isfinite(start) || (stop_defined && !(stop >= start))) {
        layer_log(inst, LOG_ERROR, "%s: invalid start time %g s / stop time %g s", function, start, stop);
        return 0;
    }
    inst->core->time = start;
    return 1;
}

void enter_initialization(Instance *inst) {
    inst->core->state = ST_INITIALIZATION;
    inst->core->initialized = 0;
    mark_dirty(inst);
    forget_rhs(inst);
}

LayerStatus exit_initialization(Instance *inst, const char *function) {
    const ModelDef *m = inst->model;
    if (run_initialize(inst, function)) {
        inst->core->state = ST_ERROR;
        return LAYER_ERROR;
    }
    inst->core->state = inst->kind == KIND_CO_SIMULATION ? ST_STEP_COMPLETE : ST_EVENT;
    solver_reset(inst->memory, m->n_states);
    inst->core->next_event_time = INFINITY;
    /* the initial event iteration (Model Exchange and Co-Simulation in event mode: the importer's own) */
    if (inst->kind == KIND_CO_SIMULATION && !inst->event_mode_used && m->update) {
        int changed = 0, terminate = 0;
        if (event_iteration(inst, function, &changed, &terminate)) {
            layer_log(inst, LOG_ERROR, "%s: the initial event iteration failed%s", function, model_error_suffix(inst));
            inst->core->state = ST_ERROR;
            return LAYER_ERROR;
        }
        if (terminate) inst->core->terminate = 1;
    }
    mark_dirty(inst);
    if (refresh(inst, 0, function) || check_finite(inst, function)) {
        inst->core->state = ST_ERROR;
        return LAYER_ERROR;
    }
    layer_log(inst, LOG_INFO, "initialized at t = %g s: %d continuous states, solver %d, internal_step %g s",
              inst->core->time, m->n_states, inst->integers[I_SOLVER], inst->reals[R_INTERNAL_STEP]);
    return LAYER_OK;
}

/* ------------------------------------------------------------- FMU state */

/* A captured FMU state: a copy of the instance block. */
typedef struct {
    size_t size;
    unsigned char data[];
} Snapshot;

static const char SERIAL_MAGIC[8] = {'M', 'F', 'M', 'U', 'S', 'T', '0', '1'};

LayerStatus state_get(Instance *inst, const char *function, void **state) {
    Snapshot *s = state ? (Snapshot *)*state : NULL;
    if (!state) return LAYER_ERROR;
    if (s && s->size != inst->block_size) {
        layer_log(inst, LOG_ERROR, "%s: the given FMU state belongs to another model", function);
        return LAYER_ERROR;
    }
    if (!s) s = malloc(sizeof(Snapshot) + inst->block_size);
    if (!s) {
        layer_log(inst, LOG_ERROR, "%s: out of memory", function);
        return LAYER_ERROR;
    }
    s->size = inst->block_size;
    memcpy(s->data, inst->block, inst->block_size);
    *state = s;
    return LAYER_OK;
}

LayerStatus state_set(Instance *inst, const char *function, const void *state) {
    const Snapshot *s = state;
    if (!s || s->size != inst->block_size) {
        layer_log(inst, LOG_ERROR, "%s: FMU state is NULL or of another model (%zu bytes, expected %zu)", function,
                  s ? s->size : 0, inst->block_size);
        return LAYER_ERROR;
    }
    memcpy(inst->block, s->data, inst->block_size);
    forget_rhs(inst); /* the locals an evaluation wrote are back as they were */
    return LAYER_OK;
}

void state_free(void **state) {
    if (state) {
        free(*state);
        *state = NULL;
    }
}

/* Serialized form: magic, block size, GUID length, GUID, block. */
static size_t serial_header_size(void) { return sizeof SERIAL_MAGIC + 2 * sizeof(uint64_t) + strlen(MODEL.guid); }

LayerStatus state_serialized_size(Instance *inst, const void *state, size_t *size) {
    const Snapshot *s = state;
    (void)inst;
    if (!s || !size) return LAYER_ERROR;
    *size = serial_header_size() + s->size;
    return LAYER_OK;
}

LayerStatus state_serialize(Instance *inst, const char *function, const void *state, unsigned char *buffer,
                            size_t size) {
    const Snapshot *s = state;
    uint64_t block = s ? s->size : 0, guid = strlen(MODEL.guid);
    unsigned char *p = buffer;
    if (!s || !p || size != serial_header_size() + s->size) {
        layer_log(inst, LOG_ERROR, "%s: buffer of %zu bytes, expected %zu", function, size,
                  s ? serial_header_size() + s->size : 0);
        return LAYER_ERROR;
    }
    memcpy(p, SERIAL_MAGIC, sizeof SERIAL_MAGIC), p += sizeof SERIAL_MAGIC;
    memcpy(p, &block, sizeof block), p += sizeof block;
    memcpy(p, &guid, sizeof guid), p += sizeof guid;
    memcpy(p, MODEL.guid, guid), p += guid;
    memcpy(p, s->data, s->size);
    return LAYER_OK;
}

LayerStatus state_deserialize(Instance *inst, const char *function, const unsigned char *buffer, size_t size,
                              void **state) {
    const unsigned char *p = buffer;
    size_t header = serial_header_size();
    uint64_t block = 0, guid = 0;
    Snapshot *s;
    if (!p || !state || size < header || memcmp(p, SERIAL_MAGIC, sizeof SERIAL_MAGIC) != 0) {
        layer_log(inst, LOG_ERROR, "%s: not a serialized state of this layer (%zu bytes)", function, size);
        return LAYER_ERROR;
    }
    memcpy(&block, p + sizeof SERIAL_MAGIC, sizeof block);
    memcpy(&guid, p + sizeof SERIAL_MAGIC + sizeof block, sizeof guid);
    if (guid != strlen(MODEL.guid) || memcmp(p + header - guid, MODEL.guid, guid) != 0) {
        layer_log(inst, LOG_ERROR, "%s: state of a foreign model (GUID differs from %s's)", function,
                  MODEL.identifier);
        return LAYER_ERROR;
    }
    if (block != inst->block_size || size != header + block) {
        layer_log(inst, LOG_ERROR, "%s: truncated or inconsistent buffer: %zu bytes, expected %zu", function, size,
                  header + inst->block_size);
        return LAYER_ERROR;
    }
    s = *state;
    if (s && s->size != inst->block_size) {
        free(s);
        s = NULL;
    }
    if (!s) s = malloc(sizeof(Snapshot) + inst->block_size);
    if (!s) {
        layer_log(inst, LOG_ERROR, "%s: out of memory", function);
        return LAYER_ERROR;
    }
    s->size = inst->block_size;
    memcpy(s->data, p + header, inst->block_size);
    *state = s;
    return LAYER_OK;
}
