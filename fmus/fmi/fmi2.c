/* fmi2.c: every FMI 2.0 function (Co-Simulation and Model Exchange in one binary).
 *
 * Argument errors (unknown value reference, wrong type, value out of range, a
 * call in the wrong state) return fmi2Error and leave the instance unchanged,
 * so the caller may go on.  Computation errors (model equations failing,
 * non-finite results) return fmi2Error and put the instance into the Error
 * state, from which only fmi2Get*, fmi2SetFMUstate, fmi2Reset and
 * fmi2FreeInstance are allowed.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "instance.h"

#define S_INST MASK(ST_INSTANTIATED)
#define S_INIT MASK(ST_INITIALIZATION)
#define S_STEP MASK(ST_STEP_COMPLETE)
#define S_EVENT MASK(ST_EVENT)
#define S_CONT MASK(ST_CONTINUOUS_TIME)
#define S_TERM MASK(ST_TERMINATED)
#define S_ERR MASK(ST_ERROR)

#define S_SET (S_INST | S_INIT | S_STEP | S_EVENT | S_CONT)
#define S_GET (S_INIT | S_STEP | S_EVENT | S_CONT | S_TERM | S_ERR)

#define GUARD(function, mask)                                         \
    Instance *inst = (Instance *)c;                                   \
    if (!inst) return fmi2Error;                                      \
    if (!check_state(inst, function, mask)) return fmi2Error

/* A captured FMU state: a copy of the instance block. */
typedef struct {
    size_t size;
    unsigned char data[];
} Snapshot;

static const char SERIAL_MAGIC[8] = {'M', 'F', 'M', 'U', 'S', 'T', '0', '1'};

/* ---------------------------------------------------------------- common */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    GUARD("fmi2SetDebugLogging", ANY_STATE);
    unsigned mask = inst->log_mask;
    if (nCategories == 0) {
        mask = loggingOn ? (1u << LOG_N_CATEGORIES) - 1u : 0u;
    } else {
        for (size_t i = 0; i < nCategories; i++) {
            int found = -1;
            for (int k = 0; k < LOG_N_CATEGORIES; k++)
                if (categories[i] && strcmp(categories[i], LOG_CATEGORY_NAMES[k]) == 0) found = k;
            if (found < 0) {
                layer_log(inst, LOG_ERROR, "fmi2SetDebugLogging: unknown log category \"%s\"",
                          categories[i] ? categories[i] : "(null)");
                return fmi2Error;
            }
            mask = loggingOn ? (mask | (1u << found)) : (mask & ~(1u << found));
        }
    }
    inst->log_mask = mask;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    fmi2CallbackLogger logger = functions ? functions->logger : NULL;
    fmi2ComponentEnvironment env = functions ? functions->componentEnvironment : NULL;
    const char *name = instanceName ? instanceName : "";
    Instance *inst;
    (void)fmuResourceLocation;
    (void)visible;
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        if (logger) logger(env, name, fmi2Error, "logError", "fmi2Instantiate: unknown fmuType %d", (int)fmuType);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, MODEL.guid) != 0) {
        if (logger)
            logger(env, name, fmi2Error, "logError", "fmi2Instantiate: GUID \"%s\" does not match %s's \"%s\"",
                   fmuGUID ? fmuGUID : "(null)", MODEL.identifier, MODEL.guid);
        return NULL;
    }
    inst = instance_new(name, fmuType, logger, env, loggingOn);
    if (!inst && logger) logger(env, name, fmi2Error, "logError", "fmi2Instantiate: out of memory");
    return inst;
}

void fmi2FreeInstance(fmi2Component c) { instance_free((Instance *)c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    GUARD("fmi2SetupExperiment", S_INST);
    (void)toleranceDefined;
    (void)tolerance;
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        layer_log(inst, LOG_ERROR, "fmi2SetupExperiment: invalid start time %g s / stop time %g s", startTime,
                  stopTime);
        return fmi2Error;
    }
    inst->core->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    GUARD("fmi2EnterInitializationMode", S_INST);
    inst->core->state = ST_INITIALIZATION;
    inst->core->initialized = 0;
    mark_dirty(inst);
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    GUARD("fmi2ExitInitializationMode", S_INIT);
    const ModelDef *m = inst->model;
    if (run_initialize(inst, "fmi2ExitInitializationMode")) {
        inst->core->state = ST_ERROR;
        return fmi2Error;
    }
    inst->core->state = inst->type == fmi2CoSimulation ? ST_STEP_COMPLETE : ST_EVENT;
    solver_reset(inst->memory, m->n_states);
    mark_dirty(inst);
    if (refresh(inst, 0, "fmi2ExitInitializationMode") || check_finite(inst, "fmi2ExitInitializationMode")) {
        inst->core->state = ST_ERROR;
        return fmi2Error;
    }
    layer_log(inst, LOG_INFO, "initialized at t = %g s: %d continuous states, solver %d, internal_step %g s",
              inst->core->time, m->n_states, inst->integers[I_SOLVER], inst->reals[R_INTERNAL_STEP]);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    GUARD("fmi2Terminate", S_STEP | S_EVENT | S_CONT);
    inst->core->state = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    GUARD("fmi2Reset", ANY_STATE);
    instance_reset(inst);
    return fmi2OK;
}

/* ------------------------------------------------------- get/set values */

/* The variable behind vr if it exists and has one of the wanted types; else logs and NULL. */
static const Variable *lookup(Instance *inst, const char *function, fmi2ValueReference vr, unsigned types) {
    const Variable *v = variable_of(inst, vr);
    static const char *const type_names[] = {"Real", "Integer", "Boolean", "String", "Enumeration"};
    if (!v) {
        layer_log(inst, LOG_ERROR, "%s: value reference %u out of range (model %s has %d variables)", function,
                  (unsigned)vr, inst->model->identifier, inst->model->n_variables);
        return NULL;
    }
    if (!(types & (1u << v->type))) {
        layer_log(inst, LOG_ERROR, "%s: variable %s (value reference %u) is of type %s", function, v->name,
                  (unsigned)vr, type_names[v->type]);
        return NULL;
    }
    return v;
}

#define T_MASK_REAL (1u << T_REAL)
#define T_MASK_INTEGER ((1u << T_INTEGER) | (1u << T_SOLVER))
#define T_MASK_BOOLEAN (1u << T_BOOLEAN)
#define T_MASK_STRING (1u << T_STRING)

static int is_derivative(const Variable *v) { return v->derivative_of != NO_STATE; }

/* Check that every vr can be set to value (NULL: non-numeric type); logs the first problem. */
static int check_settable(Instance *inst, const char *function, const fmi2ValueReference vr[], size_t nvr,
                          unsigned types, const double *values) {
    for (size_t i = 0; i < nvr; i++) {
        const Variable *v = lookup(inst, function, vr[i], types);
        const char *why;
        if (!v) return 0;
        why = not_settable_reason(inst, v);
        if (why) {
            layer_log(inst, LOG_ERROR, "%s: variable %s cannot be set in state %s: %s", function, v->name,
                      state_name(inst->core->state), why);
            return 0;
        }
        if (values && !isfinite(values[i])) {
            layer_log(inst, LOG_ERROR, "%s: variable %s: value %g is not finite", function, v->name, values[i]);
            return 0;
        }
        if (values && (values[i] < v->min || values[i] > v->max)) {
            layer_log(inst, LOG_ERROR, "%s: variable %s: value %.17g outside [%g, %g]", function, v->name,
                      values[i], v->min, v->max);
            return 0;
        }
    }
    return 1;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    GUARD("fmi2GetReal", S_GET);
    int need_derivatives = 0;
    for (size_t i = 0; i < nvr; i++) {
        const Variable *v = lookup(inst, "fmi2GetReal", vr[i], T_MASK_REAL);
        if (!v) return fmi2Error;
        need_derivatives |= is_derivative(v);
    }
    if (refresh(inst, need_derivatives, "fmi2GetReal")) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = inst->reals[inst->model->variables[vr[i]].slot];
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    GUARD("fmi2GetInteger", S_GET);
    for (size_t i = 0; i < nvr; i++)
        if (!lookup(inst, "fmi2GetInteger", vr[i], T_MASK_INTEGER)) return fmi2Error;
    if (refresh(inst, 0, "fmi2GetInteger")) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = inst->integers[inst->model->variables[vr[i]].slot];
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    GUARD("fmi2GetBoolean", S_GET);
    for (size_t i = 0; i < nvr; i++)
        if (!lookup(inst, "fmi2GetBoolean", vr[i], T_MASK_BOOLEAN)) return fmi2Error;
    if (refresh(inst, 0, "fmi2GetBoolean")) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = inst->booleans[inst->model->variables[vr[i]].slot];
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    GUARD("fmi2GetString", S_GET);
    for (size_t i = 0; i < nvr; i++)
        if (!lookup(inst, "fmi2GetString", vr[i], T_MASK_STRING)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = model_string(inst, inst->model->variables[vr[i]].slot);
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    GUARD("fmi2SetReal", S_SET);
    if (!check_settable(inst, "fmi2SetReal", vr, nvr, T_MASK_REAL, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) inst->reals[inst->model->variables[vr[i]].slot] = value[i];
    note_set(inst, vr, nvr);
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    GUARD("fmi2SetInteger", S_SET);
    for (size_t i = 0; i < nvr; i++) {
        double d = value[i];
        if (!check_settable(inst, "fmi2SetInteger", vr + i, 1, T_MASK_INTEGER, &d)) return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) inst->integers[inst->model->variables[vr[i]].slot] = value[i];
    note_set(inst, vr, nvr);
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    GUARD("fmi2SetBoolean", S_SET);
    if (!check_settable(inst, "fmi2SetBoolean", vr, nvr, T_MASK_BOOLEAN, NULL)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) inst->booleans[inst->model->variables[vr[i]].slot] = value[i] != fmi2False;
    note_set(inst, vr, nvr);
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    GUARD("fmi2SetString", S_SET);
    if (!check_settable(inst, "fmi2SetString", vr, nvr, T_MASK_STRING, NULL)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (!value[i] || strlen(value[i]) >= STRING_CAPACITY) {
            layer_log(inst, LOG_ERROR, "fmi2SetString: variable %s: value is NULL or longer than %d bytes",
                      inst->model->variables[vr[i]].name, STRING_CAPACITY - 1);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++)
        strcpy((char *)model_string(inst, inst->model->variables[vr[i]].slot), value[i]);
    note_set(inst, vr, nvr);
    return fmi2OK;
}

/* ------------------------------------------------------------ FMU state */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    GUARD("fmi2GetFMUstate", ANY_STATE);
    Snapshot *s = FMUstate ? (Snapshot *)*FMUstate : NULL;
    if (!FMUstate) return fmi2Error;
    if (s && s->size != inst->block_size) {
        layer_log(inst, LOG_ERROR, "fmi2GetFMUstate: the given FMU state belongs to another model");
        return fmi2Error;
    }
    if (!s) s = malloc(sizeof(Snapshot) + inst->block_size);
    if (!s) {
        layer_log(inst, LOG_ERROR, "fmi2GetFMUstate: out of memory");
        return fmi2Error;
    }
    s->size = inst->block_size;
    memcpy(s->data, inst->block, inst->block_size);
    *FMUstate = s;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    GUARD("fmi2SetFMUstate", ANY_STATE);
    const Snapshot *s = FMUstate;
    if (!s || s->size != inst->block_size) {
        layer_log(inst, LOG_ERROR, "fmi2SetFMUstate: FMU state is NULL or of another model (%zu bytes, expected %zu)",
                  s ? s->size : 0, inst->block_size);
        return fmi2Error;
    }
    memcpy(inst->block, s->data, inst->block_size);
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    GUARD("fmi2FreeFMUstate", ANY_STATE);
    if (FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

/* Serialized form: magic, block size, GUID length, GUID, block. */
static size_t serial_header_size(void) { return sizeof SERIAL_MAGIC + 2 * sizeof(uint64_t) + strlen(MODEL.guid); }

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    GUARD("fmi2SerializedFMUstateSize", ANY_STATE);
    const Snapshot *s = FMUstate;
    if (!s || !size) return fmi2Error;
    *size = serial_header_size() + s->size;
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    GUARD("fmi2SerializeFMUstate", ANY_STATE);
    const Snapshot *s = FMUstate;
    uint64_t block = s ? s->size : 0, guid = strlen(MODEL.guid);
    unsigned char *p = (unsigned char *)serializedState;
    if (!s || !p || size != serial_header_size() + s->size) {
        layer_log(inst, LOG_ERROR, "fmi2SerializeFMUstate: buffer of %zu bytes, expected %zu", size,
                  s ? serial_header_size() + s->size : 0);
        return fmi2Error;
    }
    memcpy(p, SERIAL_MAGIC, sizeof SERIAL_MAGIC), p += sizeof SERIAL_MAGIC;
    memcpy(p, &block, sizeof block), p += sizeof block;
    memcpy(p, &guid, sizeof guid), p += sizeof guid;
    memcpy(p, MODEL.guid, guid), p += guid;
    memcpy(p, s->data, s->size);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    GUARD("fmi2DeSerializeFMUstate", ANY_STATE);
    const unsigned char *p = (const unsigned char *)serializedState;
    size_t header = serial_header_size();
    uint64_t block = 0, guid = 0;
    Snapshot *s;
    if (!p || !FMUstate || size < header || memcmp(p, SERIAL_MAGIC, sizeof SERIAL_MAGIC) != 0) {
        layer_log(inst, LOG_ERROR, "fmi2DeSerializeFMUstate: not a serialized state of this layer (%zu bytes)",
                  size);
        return fmi2Error;
    }
    memcpy(&block, p + sizeof SERIAL_MAGIC, sizeof block);
    memcpy(&guid, p + sizeof SERIAL_MAGIC + sizeof block, sizeof guid);
    if (guid != strlen(MODEL.guid) || memcmp(p + header - guid, MODEL.guid, guid) != 0) {
        layer_log(inst, LOG_ERROR, "fmi2DeSerializeFMUstate: state of a foreign model (GUID differs from %s's)",
                  MODEL.identifier);
        return fmi2Error;
    }
    if (block != inst->block_size || size != header + block) {
        layer_log(inst, LOG_ERROR,
                  "fmi2DeSerializeFMUstate: truncated or inconsistent buffer: %zu bytes, expected %zu",
                  size, header + inst->block_size);
        return fmi2Error;
    }
    s = *FMUstate;
    if (s && s->size != inst->block_size) {
        free(s);
        s = NULL;
    }
    if (!s) s = malloc(sizeof(Snapshot) + inst->block_size);
    if (!s) {
        layer_log(inst, LOG_ERROR, "fmi2DeSerializeFMUstate: out of memory");
        return fmi2Error;
    }
    s->size = inst->block_size;
    memcpy(s->data, p + header, inst->block_size);
    *FMUstate = s;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    GUARD("fmi2GetDirectionalDerivative", S_INIT | S_STEP | S_EVENT | S_CONT | S_TERM);
    return directional_derivative(inst, vUnknown_ref, nUnknown, vKnown_ref, nKnown, dvKnown, dvUnknown);
}

/* --------------------------------------------------------- co-simulation */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    GUARD("fmi2SetRealInputDerivatives", S_INST | S_INIT | S_STEP);
    if (inst->type != fmi2CoSimulation) {
        layer_log(inst, LOG_ERROR, "fmi2SetRealInputDerivatives: only for Co-Simulation");
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        const Variable *v = lookup(inst, "fmi2SetRealInputDerivatives", vr[i], T_MASK_REAL);
        if (!v) return fmi2Error;
        if (inst->input_index[vr[i]] < 0) {
            layer_log(inst, LOG_ERROR, "fmi2SetRealInputDerivatives: variable %s is not an input", v->name);
            return fmi2Error;
        }
        if (order[i] < 1 || order[i] > MAX_INPUT_ORDER) {
            layer_log(inst, LOG_ERROR, "fmi2SetRealInputDerivatives: variable %s: order %d not in 1..%d", v->name,
                      (int)order[i], MAX_INPUT_ORDER);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            layer_log(inst, LOG_ERROR, "fmi2SetRealInputDerivatives: variable %s: derivative %g is not finite",
                      v->name, value[i]);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++)
        inst->input_derivs[(size_t)inst->input_index[vr[i]] * MAX_INPUT_ORDER + (size_t)(order[i] - 1)] = value[i];
    inst->core->have_input_derivatives = 1;
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    GUARD("fmi2GetRealOutputDerivatives", S_GET);
    (void)vr, (void)nvr, (void)order, (void)value;
    layer_log(inst, LOG_ERROR, "fmi2GetRealOutputDerivatives: not supported (maxOutputDerivativeOrder = 0)");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    GUARD("fmi2DoStep", S_STEP);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst->type != fmi2CoSimulation) {
        layer_log(inst, LOG_ERROR, "fmi2DoStep: instance was created for Model Exchange");
        return fmi2Error;
    }
    return do_step(inst, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    GUARD("fmi2CancelStep", ANY_STATE);
    layer_log(inst, LOG_ERROR, "fmi2CancelStep: steps are synchronous, nothing to cancel");
    return fmi2Error;
}

static fmi2Status no_status(Instance *inst, const char *function) {
    layer_log(inst, LOG_ERROR, "%s: not supported (steps are synchronous)", function);
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    GUARD("fmi2GetStatus", ANY_STATE);
    (void)s, (void)value;
    return no_status(inst, "fmi2GetStatus");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    GUARD("fmi2GetRealStatus", ANY_STATE);
    if (s == fmi2LastSuccessfulTime && value) {
        *value = inst->core->time;
        return fmi2OK;
    }
    return no_status(inst, "fmi2GetRealStatus");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    GUARD("fmi2GetIntegerStatus", ANY_STATE);
    (void)s, (void)value;
    return no_status(inst, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    GUARD("fmi2GetBooleanStatus", ANY_STATE);
    if (s == fmi2Terminated && value) {
        *value = inst->core->terminate ? fmi2True : fmi2False;
        return fmi2OK;
    }
    return no_status(inst, "fmi2GetBooleanStatus");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    GUARD("fmi2GetStringStatus", ANY_STATE);
    (void)s, (void)value;
    return no_status(inst, "fmi2GetStringStatus");
}

/* -------------------------------------------------------- model exchange */

static int check_nx(Instance *inst, const char *function, size_t nx) {
    if (nx == (size_t)inst->model->n_states) return 1;
    layer_log(inst, LOG_ERROR, "%s: nx = %zu but the model has %d continuous states", function, nx,
              inst->model->n_states);
    return 0;
}

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    GUARD("fmi2EnterEventMode", S_EVENT | S_CONT);
    inst->core->state = ST_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    GUARD("fmi2NewDiscreteStates", S_EVENT);
    if (eventInfo) {
        eventInfo->newDiscreteStatesNeeded = fmi2False;
        eventInfo->terminateSimulation = fmi2False;
        eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
        eventInfo->valuesOfContinuousStatesChanged = fmi2False;
        eventInfo->nextEventTimeDefined = fmi2False;
        eventInfo->nextEventTime = 0.0;
    }
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    GUARD("fmi2EnterContinuousTimeMode", S_EVENT);
    inst->core->state = ST_CONTINUOUS_TIME;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    GUARD("fmi2CompletedIntegratorStep", S_CONT);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (enterEventMode) *enterEventMode = fmi2False;
    if (terminateSimulation) *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    GUARD("fmi2SetTime", S_EVENT | S_CONT);
    if (!isfinite(time)) {
        layer_log(inst, LOG_ERROR, "fmi2SetTime: time %g is not finite", time);
        return fmi2Error;
    }
    inst->core->time = time;
    mark_dirty(inst);
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    GUARD("fmi2SetContinuousStates", S_CONT);
    if (!check_nx(inst, "fmi2SetContinuousStates", nx)) return fmi2Error;
    for (size_t i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            layer_log(inst, LOG_ERROR, "fmi2SetContinuousStates: state %zu = %g is not finite at t = %.17g", i,
                      x[i], inst->core->time);
            return fmi2Error;
        }
    }
    scatter_states(inst, x);
    mark_dirty(inst);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    GUARD("fmi2GetDerivatives", S_INIT | S_EVENT | S_CONT | S_TERM);
    if (!check_nx(inst, "fmi2GetDerivatives", nx)) return fmi2Error;
    if (refresh(inst, 1, "fmi2GetDerivatives")) {
        inst->core->state = ST_ERROR;
        return fmi2Error;
    }
    for (size_t i = 0; i < nx; i++) derivatives[i] = inst->reals[inst->model->derivative_slots[i]];
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    GUARD("fmi2GetEventIndicators", S_INIT | S_EVENT | S_CONT | S_TERM);
    (void)eventIndicators;
    if (ni != 0) {
        layer_log(inst, LOG_ERROR, "fmi2GetEventIndicators: ni = %zu but the model has no event indicators", ni);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    GUARD("fmi2GetContinuousStates", S_INIT | S_EVENT | S_CONT | S_TERM);
    if (!check_nx(inst, "fmi2GetContinuousStates", nx)) return fmi2Error;
    gather_states(inst, x);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    GUARD("fmi2GetNominalsOfContinuousStates", S_INST | S_EVENT | S_CONT | S_TERM);
    if (!check_nx(inst, "fmi2GetNominalsOfContinuousStates", nx)) return fmi2Error;
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}
