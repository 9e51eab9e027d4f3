/* fmi3.c: the FMI 3.0 Co-Simulation interface of the shared layer.
 *
 * A thin interface like fmi2.c: the instance, its state machine and settability
 * rules, the get/set checks, the step, FMU state copies and directional derivatives
 * are the layer's (instance.c, step.c, derivative.c, log.c), so both versions behave
 * alike.  What is FMI 3.0's own:
 *   - every value type (Float32 .. UInt64, Boolean, String, Binary; Enumerations through
 *     fmi3Get/SetInt64) and arrays: nValues counts the elements of all variables asked for;
 *   - `time`, the independent variable, at value reference n_variables (the tables do not
 *     list it);
 *   - fmi3EnterInitializationMode takes the experiment's start and stop time;
 *   - fmi3DoStep: when the model ends the simulation (MODEL_TERMINATE) the step completes
 *     and returns fmi3OK with *terminateSimulation = fmi3True;
 *   - Event Mode of Co-Simulation (hasEventMode="true" for a model with events): instantiated with
 *     eventModeUsed, the instance is in Event Mode after fmi3ExitInitializationMode, and doStep stops
 *     at an event (time, state or step event) before handling it: *eventHandlingNeeded, the time and
 *     states those at the event, its outputs those before it.  With earlyReturnAllowed it stops at
 *     the first event (*earlyReturn where that is before the step's end, *lastSuccessfulTime the
 *     event's time); without, events inside the step are handled there as without event mode and
 *     only one at the step's end is left.  The importer then calls fmi3EnterEventMode,
 *     fmi3UpdateDiscreteStates (the model's event update) until no update is needed, and
 *     fmi3EnterStepMode; a doStep from the time it returned early at to the step's end goes on with
 *     the step's grid of internal steps;
 *   - Step Mode is the state StepComplete of FMI 2.0: the same rules apply;
 *   - intermediate update (providesIntermediateUpdate where the model has continuous Float64
 *     inputs, declared intermediateUpdate="true"): given the callback, doStep asks the importer for
 *     those inputs at each new stage time of its solver (step.c) and uses what it sets there;
 *   - Model Exchange as FMI 2.0's (the model's event indicators, event update and step events,
 *     nominals 1): after fmi3ExitInitializationMode the instance is in Event Mode,
 *     fmi3UpdateDiscreteStates runs the model's event update, fmi3EnterContinuousTimeMode, then
 *     the states, time and derivatives.
 *   - Scheduled Execution for a model with clocks (clocks.c): fmi3ActivateModelPartition,
 *     fmi3GetClock of output clocks, fmi3GetIntervalDecimal; its Clock Activation Mode is Step Mode.
 * Not supported (the function exists and returns fmi3Error, or NULL for an instance):
 * fmi3SetClock and the other interval and shift calls, Configuration Mode, early return after an
 * intermediate update, intermediate variables to get, output derivatives, adjoint derivatives,
 * variable dependency queries.
 */
#include <stdio.h>
#include <string.h>

#include "fmi3Functions.h"
#include "instance.h"

#define GUARD(function, mask)                                         \
    Instance *inst = (Instance *)instance;                            \
    if (!inst) return fmi3Error;                                      \
    if (!check_state(inst, function, mask)) return fmi3Error

/* The value reference arrays of the layer are unsigned int; fmi3ValueReference is uint32_t. */
typedef char value_reference_is_unsigned_int[sizeof(fmi3ValueReference) == sizeof(unsigned) ? 1 : -1];

static void emit(const Instance *inst, LayerStatus status, const char *category, const char *message) {
    ((fmi3LogMessageCallback)inst->logger)(inst->env, (fmi3Status)status, category, message);
}

/* Why a Co-Simulation instance refuses the calls of Event Mode. */
#define NO_EVENT_MODE "the FMU has no Event Mode or was instantiated without eventModeUsed"

static fmi3Status unsupported(Instance *inst, const char *function, const char *why) {
    if (inst) layer_log(inst, LOG_ERROR, "%s: not supported (%s)", function, why);
    return fmi3Error;
}

/* ---------------------------------------------------------------- common */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    GUARD("fmi3SetDebugLogging", ANY_STATE);
    return (fmi3Status)set_debug_logging(inst, "fmi3SetDebugLogging", loggingOn, nCategories, categories);
}

/* providesIntermediateUpdate: the model has inputs to ask for (master/fmubuild.py declares it so). */
static int has_intermediate_inputs(void) {
    for (int vr = 0; vr < MODEL.n_variables; vr++)
        if (intermediate_input(&MODEL.variables[vr])) return 1;
    return 0;
}

/* step.c inputs_at: the importer sets the intermediate-update inputs of time t inside its callback
 * (Intermediate Update Mode: fmi3SetFloat64 of those inputs only).  The FMU never returns early. */
static void ask_intermediate_inputs(Instance *inst, double t) {
    fmi3Boolean early = fmi3False;
    fmi3Float64 early_time = t;
    inst->in_intermediate_update = 1;
    ((fmi3IntermediateUpdateCallback)inst->callback)(inst->env, t, fmi3True, fmi3False, fmi3False, fmi3False,
                                                     &early, &early_time);
    inst->in_intermediate_update = 0;
}

/* Whether an instantiation token is this model's; where not, one log line from `function`. */
static int token_matches(const char *function, fmi3String token, fmi3InstanceEnvironment environment,
                         fmi3LogMessageCallback logMessage) {
    char message[512];
    if (token && strcmp(token, MODEL.guid) == 0) return 1;
    snprintf(message, sizeof message, "%s: instantiation token \"%s\" does not match %s's \"%s\"", function,
             token ? token : "(null)", MODEL.identifier, MODEL.guid);
    if (logMessage) logMessage(environment, fmi3Error, "logError", message);
    return 0;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    const char *name = instanceName ? instanceName : "";
    char message[512];
    Instance *inst;
    /* A model without events has no Event Mode (hasEventMode="false"): eventModeUsed changes nothing
     * there.  No intermediate variables are offered. */
    (void)resourcePath, (void)visible;
    (void)requiredIntermediateVariables, (void)nRequiredIntermediateVariables;
    if (MODEL.me_only || MODEL.activate) { /* its description has no CoSimulation */
        snprintf(message, sizeof message, "fmi3InstantiateCoSimulation: %s offers %s only", MODEL.identifier,
                 MODEL.activate ? "Scheduled Execution" : "Model Exchange");
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logError", message);
        return NULL;
    }
    if (!token_matches("fmi3InstantiateCoSimulation", instantiationToken, instanceEnvironment, logMessage))
        return NULL;
    inst = instance_new(name, KIND_CO_SIMULATION, 3, emit, (void (*)(void))logMessage, instanceEnvironment,
                        loggingOn);
    if (!inst && logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logError", "fmi3InstantiateCoSimulation: out of memory");
    if (inst && intermediateUpdate && has_intermediate_inputs()) {
        inst->callback = (void (*)(void))intermediateUpdate;
        inst->ask_inputs = ask_intermediate_inputs;
    }
    if (inst && eventModeUsed && model_has_events(inst->model)) {
        inst->event_mode_used = 1;
        inst->early_return_allowed = earlyReturnAllowed != 0;
    }
    return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    const char *name = instanceName ? instanceName : "";
    Instance *inst;
    (void)resourcePath, (void)visible;
    if (!token_matches("fmi3InstantiateModelExchange", instantiationToken, instanceEnvironment, logMessage))
        return NULL;
    inst = instance_new(name, KIND_MODEL_EXCHANGE, 3, emit, (void (*)(void))logMessage, instanceEnvironment,
                        loggingOn);
    if (!inst && logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logError", "fmi3InstantiateModelExchange: out of memory");
    return inst;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    const char *name = instanceName ? instanceName : "";
    Instance *inst;
    (void)resourcePath, (void)visible, (void)lockPreemption, (void)unlockPreemption; /* no preemption */
    if (!MODEL.activate) { /* a model with partitions (a Co-Simulation one may have output clocks) */
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logError",
                       "fmi3InstantiateScheduledExecution: this FMU offers FMI 3.0 Co-Simulation only");
        return NULL;
    }
    if (!token_matches("fmi3InstantiateScheduledExecution", instantiationToken, instanceEnvironment, logMessage))
        return NULL;
    inst = instance_new(name, KIND_CO_SIMULATION, 3, emit, (void (*)(void))logMessage, instanceEnvironment,
                        loggingOn);
    if (!inst) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logError", "fmi3InstantiateScheduledExecution: out of memory");
        return NULL;
    }
    inst->scheduled = 1; /* clocks.c */
    inst->clock_update = (void (*)(void *))clockUpdate;
    return inst;
}

void fmi3FreeInstance(fmi3Instance instance) { instance_free((Instance *)instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    GUARD("fmi3EnterInitializationMode", S_INST);
    (void)toleranceDefined, (void)tolerance;
    if (!setup_experiment(inst, "fmi3EnterInitializationMode", startTime, stopTimeDefined, stopTime))
        return fmi3Error;
    enter_initialization(inst);
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    GUARD("fmi3ExitInitializationMode", S_INIT);
    LayerStatus status = exit_initialization(inst, "fmi3ExitInitializationMode");
    if (status <= LAYER_WARNING && inst->event_mode_used) inst->core->state = ST_EVENT; /* Co-Simulation's too */
    return (fmi3Status)status;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    GUARD("fmi3EnterEventMode", ANY_STATE);
    if (inst->kind == KIND_CO_SIMULATION && !inst->event_mode_used)
        return unsupported(inst, "fmi3EnterEventMode", NO_EVENT_MODE);
    if (!check_state(inst, "fmi3EnterEventMode", inst->kind == KIND_CO_SIMULATION ? S_STEP : S_EVENT | S_CONT))
        return fmi3Error;
    inst->core->state = ST_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    GUARD("fmi3Terminate", S_STEP | S_EVENT | S_CONT);
    inst->core->state = ST_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    GUARD("fmi3Reset", ANY_STATE);
    instance_reset(inst);
    return fmi3OK;
}

/* ------------------------------------------------------- get/set values */

#define M(t) TYPE_MASK(t)

/* Where a value of each type lives (model.h): reals for Float32/Float64, ints for Int32 and
 * Enumerations, int64s for the other signed and the narrower unsigned integers, uint64s. */
static double load_real(const Instance *inst, const Variable *v, size_t k) {
    return v->causality == C_INDEPENDENT ? inst->core->time : inst->reals[(size_t)v->slot + k];
}

static void store_real(Instance *inst, const Variable *v, size_t k, double x) {
    inst->reals[(size_t)v->slot + k] = x;
}

static int64_t load_int(const Instance *inst, const Variable *v, size_t k) {
    size_t s = (size_t)v->slot + k;
    return v->type == T_INTEGER || v->type == T_SOLVER ? inst->integers[s] : inst->int64s[s];
}

static void store_int(Instance *inst, const Variable *v, size_t k, int64_t x) {
    size_t s = (size_t)v->slot + k;
    if (v->type == T_INTEGER || v->type == T_SOLVER)
        inst->integers[s] = (int)x; /* Int32 values, or Enumerations checked against [min, max] */
    else
        inst->int64s[s] = x;
}

static uint64_t load_uint64(const Instance *inst, const Variable *v, size_t k) {
    return inst->uint64s[(size_t)v->slot + k];
}

static void store_uint64(Instance *inst, const Variable *v, size_t k, uint64_t x) {
    inst->uint64s[(size_t)v->slot + k] = x;
}

static fmi3Boolean load_bool(const Instance *inst, const Variable *v, size_t k) {
    return inst->booleans[(size_t)v->slot + k] != 0;
}

static void store_bool(Instance *inst, const Variable *v, size_t k, fmi3Boolean x) {
    inst->booleans[(size_t)v->slot + k] = x ? 1 : 0;
}

/* fmi3Get<Name> and fmi3Set<Name> for values of C type `CType` in variables of the types in
 * `mask`, read and written through load/store.  VALUE_AT: the values as doubles for the checks
 * of a set (finite, inside [min, max]); NULL for Booleans. */
#define ACCESSORS(Name, CType, mask, load, store, VALUE_AT)                                                   \
    fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, CType values[], \
                             size_t nValues) {                                                                \
        GUARD("fmi3Get" #Name, S_GET);                                                                        \
        size_t j = 0;                                                                                         \
        if (!prepare_get(inst, "fmi3Get" #Name, vr, nvr, mask, nValues)) return fmi3Error;                    \
        for (size_t i = 0; i < nvr; i++) {                                                                    \
            const Variable *v = variable_of(inst, vr[i]);                                                     \
            size_t n = variable_size(inst, vr[i]);                                                            \
            for (size_t k = 0; k < n; k++) values[j++] = (CType)load(inst, v, k);                             \
        }                                                                                                     \
        return fmi3OK;                                                                                        \
    }                                                                                                         \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,                \
                             const CType values[], size_t nValues) {                                          \
        GUARD("fmi3Set" #Name, S_SET);                                                                        \
        size_t j = 0;                                                                                         \
        if (!check_access(inst, "fmi3Set" #Name, vr, nvr, mask, nValues, 1, VALUE_AT, values))               \
            return fmi3Error;                                                                                 \
        for (size_t i = 0; i < nvr; i++) {                                                                    \
            const Variable *v = variable_of(inst, vr[i]);                                                     \
            size_t n = variable_size(inst, vr[i]);                                                            \
            for (size_t k = 0; k < n; k++) store(inst, v, k, values[j++]);                                    \
        }                                                                                                     \
        note_set(inst, vr, nvr);                                                                              \
        return fmi3OK;                                                                                        \
    }

#define AS_DOUBLE(Name, CType) \
    static double Name##_at(const void *values, size_t j) { return (double)((const CType *)values)[j]; }

AS_DOUBLE(Float32, fmi3Float32)
AS_DOUBLE(Float64, fmi3Float64)
AS_DOUBLE(Int8, fmi3Int8)
AS_DOUBLE(UInt8, fmi3UInt8)
AS_DOUBLE(Int16, fmi3Int16)
AS_DOUBLE(UInt16, fmi3UInt16)
AS_DOUBLE(Int32, fmi3Int32)
AS_DOUBLE(UInt32, fmi3UInt32)
AS_DOUBLE(Int64, fmi3Int64)
AS_DOUBLE(UInt64, fmi3UInt64)

ACCESSORS(Float32, fmi3Float32, M(T_FLOAT32), load_real, store_real, Float32_at)
ACCESSORS(Float64, fmi3Float64, M(T_REAL), load_real, store_real, Float64_at)
ACCESSORS(Int8, fmi3Int8, M(T_INT8), load_int, store_int, Int8_at)
ACCESSORS(UInt8, fmi3UInt8, M(T_UINT8), load_int, store_int, UInt8_at)
ACCESSORS(Int16, fmi3Int16, M(T_INT16), load_int, store_int, Int16_at)
ACCESSORS(UInt16, fmi3UInt16, M(T_UINT16), load_int, store_int, UInt16_at)
ACCESSORS(Int32, fmi3Int32, M(T_INTEGER), load_int, store_int, Int32_at)
ACCESSORS(UInt32, fmi3UInt32, M(T_UINT32), load_int, store_int, UInt32_at)
ACCESSORS(Int64, fmi3Int64, M(T_INT64) | M(T_SOLVER), load_int, store_int, Int64_at)
ACCESSORS(UInt64, fmi3UInt64, M(T_UINT64), load_uint64, store_uint64, UInt64_at)
ACCESSORS(Boolean, fmi3Boolean, M(T_BOOLEAN), load_bool, store_bool, NULL)

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3String values[],
                         size_t nValues) {
    GUARD("fmi3GetString", S_GET);
    size_t j = 0;
    if (!prepare_get(inst, "fmi3GetString", vr, nvr, M(T_STRING), nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        const Variable *v = variable_of(inst, vr[i]);
        size_t n = variable_size(inst, vr[i]);
        for (size_t k = 0; k < n; k++) values[j++] = model_string(inst, v->slot + (int)k);
    }
    return fmi3OK;
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const fmi3String values[], size_t nValues) {
    GUARD("fmi3SetString", S_SET);
    size_t j = 0;
    if (!check_access(inst, "fmi3SetString", vr, nvr, M(T_STRING), nValues, 1, NULL, NULL)) return fmi3Error;
    for (j = 0; j < nValues; j++) {
        if (!values[j] || strlen(values[j]) >= STRING_CAPACITY) {
            layer_log(inst, LOG_ERROR, "fmi3SetString: value %zu is NULL or longer than %d bytes", j,
                      STRING_CAPACITY - 1);
            return fmi3Error;
        }
    }
    j = 0;
    for (size_t i = 0; i < nvr; i++) {
        const Variable *v = variable_of(inst, vr[i]);
        size_t n = variable_size(inst, vr[i]);
        for (size_t k = 0; k < n; k++) model_set_string(inst, v->slot + (int)k, values[j++]);
    }
    note_set(inst, vr, nvr);
    return fmi3OK;
}

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    GUARD("fmi3GetBinary", S_GET);
    size_t j = 0;
    if (!prepare_get(inst, "fmi3GetBinary", vr, nvr, M(T_BINARY), nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        const Variable *v = variable_of(inst, vr[i]);
        size_t n = variable_size(inst, vr[i]);
        for (size_t k = 0; k < n; k++, j++) values[j] = model_binary(inst, v->slot + (int)k, &valueSizes[j]);
    }
    return fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    GUARD("fmi3SetBinary", S_SET);
    size_t j = 0;
    if (!check_access(inst, "fmi3SetBinary", vr, nvr, M(T_BINARY), nValues, 1, NULL, NULL)) return fmi3Error;
    for (j = 0; j < nValues; j++) {
        if (valueSizes[j] > BINARY_CAPACITY || (!values[j] && valueSizes[j] > 0)) {
            layer_log(inst, LOG_ERROR, "fmi3SetBinary: value %zu: %zu bytes (at most %d, and not NULL)", j,
                      valueSizes[j], BINARY_CAPACITY);
            return fmi3Error;
        }
    }
    j = 0;
    for (size_t i = 0; i < nvr; i++) {
        const Variable *v = variable_of(inst, vr[i]);
        size_t n = variable_size(inst, vr[i]);
        for (size_t k = 0; k < n; k++, j++) model_set_binary(inst, v->slot + (int)k, values[j], valueSizes[j]);
    }
    note_set(inst, vr, nvr);
    return fmi3OK;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    GUARD("fmi3GetClock", ANY_STATE);
    if (!MODEL.n_clocks) return unsupported(inst, "fmi3GetClock", "the FMU has no clocks");
    for (size_t i = 0; i < nvr; i++) { /* one at a time: fmi3Clock is a bool, the layer's an int */
        int ticked = 0;
        LayerStatus st = clock_get(inst, "fmi3GetClock", &vr[i], 1, &ticked);
        if (st != LAYER_OK) return (fmi3Status)st;
        values[i] = ticked ? fmi3ClockActive : fmi3ClockInactive;
    }
    return fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Clock values[]) {
    GUARD("fmi3SetClock", ANY_STATE);
    if (!MODEL.n_clocks || MODEL.activate) /* Scheduled Execution: its partitions are activated instead */
        return unsupported(inst, "fmi3SetClock", MODEL.n_clocks ? "its input clocks tick through their partitions"
                                                                : "the FMU has no clocks");
    for (size_t i = 0; i < nvr; i++) { /* one at a time: fmi3Clock is a bool, the layer's an int */
        int active = values[i] != fmi3ClockInactive;
        LayerStatus st = clock_set(inst, "fmi3SetClock", &vr[i], 1, &active);
        if (st != LAYER_OK) return (fmi3Status)st;
    }
    return fmi3OK;
}

/* -------------------------------------------------------- dependencies */

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    GUARD("fmi3GetNumberOfVariableDependencies", ANY_STATE);
    (void)valueReference, (void)nDependencies;
    return unsupported(inst, "fmi3GetNumberOfVariableDependencies", "see ModelStructure in modelDescription.xml");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    GUARD("fmi3GetVariableDependencies", ANY_STATE);
    (void)dependent, (void)elementIndicesOfDependent, (void)independents, (void)elementIndicesOfIndependents;
    (void)dependencyKinds, (void)nDependencies;
    return unsupported(inst, "fmi3GetVariableDependencies", "see ModelStructure in modelDescription.xml");
}

/* ------------------------------------------------------------ FMU state */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    GUARD("fmi3GetFMUState", ANY_STATE);
    return (fmi3Status)state_get(inst, "fmi3GetFMUState", FMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    GUARD("fmi3SetFMUState", ANY_STATE);
    return (fmi3Status)state_set(inst, "fmi3SetFMUState", FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    GUARD("fmi3FreeFMUState", ANY_STATE);
    state_free(FMUState);
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    GUARD("fmi3SerializedFMUStateSize", ANY_STATE);
    return (fmi3Status)state_serialized_size(inst, FMUState, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    GUARD("fmi3SerializeFMUState", ANY_STATE);
    return (fmi3Status)state_serialize(inst, "fmi3SerializeFMUState", FMUState, serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    GUARD("fmi3DeserializeFMUState", ANY_STATE);
    return (fmi3Status)state_deserialize(inst, "fmi3DeserializeFMUState", serializedState, size, FMUState);
}

/* ---------------------------------------------------------- derivatives */

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                        size_t nSensitivity) {
    GUARD("fmi3GetDirectionalDerivative", S_INIT | S_STEP | S_EVENT | S_CONT | S_TERM);
    if (nSeed != nKnowns || nSensitivity != nUnknowns) {
        layer_log(inst, LOG_ERROR,
                  "fmi3GetDirectionalDerivative: %zu seeds for %zu knowns, %zu sensitivities for %zu unknowns "
                  "(scalar Float64 variables only)",
                  nSeed, nKnowns, nSensitivity, nUnknowns);
        return fmi3Error;
    }
    return (fmi3Status)directional_derivative(inst, "fmi3GetDirectionalDerivative", unknowns, nUnknowns, knowns,
                                              nKnowns, seed, sensitivity);
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    GUARD("fmi3GetAdjointDerivative", ANY_STATE);
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    return unsupported(inst, "fmi3GetAdjointDerivative", "providesAdjointDerivatives=\"false\"");
}

/* ------------------------------------- configuration, clocks, event mode */

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    GUARD("fmi3EnterConfigurationMode", ANY_STATE);
    return unsupported(inst, "fmi3EnterConfigurationMode", "the FMU has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    GUARD("fmi3ExitConfigurationMode", ANY_STATE);
    return unsupported(inst, "fmi3ExitConfigurationMode", "the FMU has no structural parameters");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    GUARD("fmi3GetIntervalDecimal", ANY_STATE);
    if (!MODEL.n_clocks) return unsupported(inst, "fmi3GetIntervalDecimal", "the FMU has no clocks");
    for (size_t i = 0; i < nvr; i++) {
        int qualifier = 0;
        LayerStatus st = clock_intervals(inst, "fmi3GetIntervalDecimal", &vr[i], 1, &intervals[i], &qualifier);
        if (st != LAYER_OK) return (fmi3Status)st;
        qualifiers[i] = (fmi3IntervalQualifier)qualifier;
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    GUARD("fmi3GetIntervalFraction", ANY_STATE);
    (void)vr, (void)nvr, (void)counters, (void)resolutions, (void)qualifiers;
    return unsupported(inst, "fmi3GetIntervalFraction", "the FMU has no clocks");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    GUARD("fmi3GetShiftDecimal", ANY_STATE);
    (void)vr, (void)nvr, (void)shifts;
    return unsupported(inst, "fmi3GetShiftDecimal", "the FMU has no clocks");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    GUARD("fmi3GetShiftFraction", ANY_STATE);
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return unsupported(inst, "fmi3GetShiftFraction", "the FMU has no clocks");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    GUARD("fmi3SetIntervalDecimal", ANY_STATE);
    (void)vr, (void)nvr, (void)intervals;
    return unsupported(inst, "fmi3SetIntervalDecimal", "the FMU has no clocks");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    GUARD("fmi3SetIntervalFraction", ANY_STATE);
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return unsupported(inst, "fmi3SetIntervalFraction", "the FMU has no clocks");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    GUARD("fmi3SetShiftDecimal", ANY_STATE);
    (void)vr, (void)nvr, (void)shifts;
    return unsupported(inst, "fmi3SetShiftDecimal", "the FMU has no clocks");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    GUARD("fmi3SetShiftFraction", ANY_STATE);
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return unsupported(inst, "fmi3SetShiftFraction", "the FMU has no clocks");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    GUARD("fmi3EvaluateDiscreteStates", ANY_STATE);
    return unsupported(inst, "fmi3EvaluateDiscreteStates", "providesEvaluateDiscreteStates=\"false\"");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    GUARD("fmi3UpdateDiscreteStates", ANY_STATE);
    if (inst->kind == KIND_CO_SIMULATION && !inst->event_mode_used)
        return unsupported(inst, "fmi3UpdateDiscreteStates", NO_EVENT_MODE);
    if (!check_state(inst, "fmi3UpdateDiscreteStates", S_EVENT)) return fmi3Error;
    int needed = 0, changed = 0, terminate = 0;
    if (event_update(inst, "fmi3UpdateDiscreteStates", &needed, &changed, &terminate)) {
        inst->core->state = ST_ERROR;
        return inst->core->fatal ? fmi3Fatal : fmi3Error;
    }
    const int timed = isfinite(inst->core->next_event_time);
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = needed && !terminate;
    if (terminateSimulation) *terminateSimulation = terminate != 0;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = changed != 0;
    if (nextEventTimeDefined) *nextEventTimeDefined = timed != 0;
    if (nextEventTime) *nextEventTime = timed ? inst->core->next_event_time : 0.0;
    return fmi3OK;
}

/* -------------------------------------------------------- model exchange */

/* A Model Exchange call of a Model Exchange instance in one of the states `mask`. */
#define ME_GUARD(function, mask)                                                                      \
    GUARD(function, ANY_STATE);                                                                       \
    if (inst->kind != KIND_MODEL_EXCHANGE)                                                            \
        return unsupported(inst, function, "a Co-Simulation instance (fmi3InstantiateModelExchange)"); \
    if (!check_state(inst, function, mask)) return fmi3Error

static int check_nx(Instance *inst, const char *function, size_t nx) {
    if (nx == (size_t)inst->model->n_states) return 1;
    layer_log(inst, LOG_ERROR, "%s: nContinuousStates = %zu but the model has %d continuous states", function, nx,
              inst->model->n_states);
    return 0;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    ME_GUARD("fmi3EnterContinuousTimeMode", S_EVENT);
    inst->core->state = ST_CONTINUOUS_TIME;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    ME_GUARD("fmi3CompletedIntegratorStep", S_CONT);
    (void)noSetFMUStatePriorToCurrentPoint;
    int event = 0;
    if (inst->model->step_event) {
        gather_states(inst, inst->x);
        event = inst->model->step_event(inst, inst->core->time, inst->x) != 0;
    }
    if (enterEventMode) *enterEventMode = event != 0;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    ME_GUARD("fmi3SetTime", S_EVENT | S_CONT);
    if (!isfinite(time)) {
        layer_log(inst, LOG_ERROR, "fmi3SetTime: time %g is not finite", time);
        return fmi3Error;
    }
    inst->core->time = time;
    mark_dirty(inst);
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    ME_GUARD("fmi3SetContinuousStates", S_CONT);
    if (!check_nx(inst, "fmi3SetContinuousStates", nContinuousStates)) return fmi3Error;
    for (size_t i = 0; i < nContinuousStates; i++) {
        if (!isfinite(continuousStates[i])) {
            layer_log(inst, LOG_ERROR, "fmi3SetContinuousStates: state %zu = %g is not finite at t = %.17g", i,
                      continuousStates[i], inst->core->time);
            return fmi3Error;
        }
    }
    scatter_states(inst, continuousStates);
    mark_dirty(inst);
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    ME_GUARD("fmi3GetContinuousStateDerivatives", S_INIT | S_EVENT | S_CONT | S_TERM);
    if (!check_nx(inst, "fmi3GetContinuousStateDerivatives", nContinuousStates)) return fmi3Error;
    if (refresh(inst, 1, "fmi3GetContinuousStateDerivatives")) {
        inst->core->state = ST_ERROR;
        return fmi3Error;
    }
    for (size_t i = 0; i < nContinuousStates; i++) derivatives[i] = inst->reals[inst->model->derivative_slots[i]];
    return fmi3OK;
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    ME_GUARD("fmi3GetEventIndicators", S_INIT | S_EVENT | S_CONT | S_TERM);
    if (nEventIndicators != (size_t)inst->model->n_event_indicators) {
        layer_log(inst, LOG_ERROR, "fmi3GetEventIndicators: %zu asked but the model has %d event indicators",
                  nEventIndicators, inst->model->n_event_indicators);
        return fmi3Error;
    }
    if (event_indicators_now(inst, inst->z)) {
        layer_log(inst, LOG_ERROR, "fmi3GetEventIndicators: the model's event indicators failed at t = %.17g s%s",
                  inst->core->time, model_error_suffix(inst));
        inst->core->state = ST_ERROR;
        return inst->core->fatal ? fmi3Fatal : fmi3Error;
    }
    for (size_t i = 0; i < nEventIndicators; i++) eventIndicators[i] = inst->z[i];
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    ME_GUARD("fmi3GetContinuousStates", S_INIT | S_EVENT | S_CONT | S_TERM);
    if (!check_nx(inst, "fmi3GetContinuousStates", nContinuousStates)) return fmi3Error;
    gather_states(inst, continuousStates);
    return fmi3OK;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    ME_GUARD("fmi3GetNominalsOfContinuousStates", S_INIT | S_EVENT | S_CONT | S_TERM);
    if (!check_nx(inst, "fmi3GetNominalsOfContinuousStates", nContinuousStates)) return fmi3Error;
    for (size_t i = 0; i < nContinuousStates; i++) nominals[i] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    ME_GUARD("fmi3GetNumberOfEventIndicators", ANY_STATE);
    if (nEventIndicators) *nEventIndicators = (size_t)inst->model->n_event_indicators;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    ME_GUARD("fmi3GetNumberOfContinuousStates", ANY_STATE);
    if (nContinuousStates) *nContinuousStates = (size_t)inst->model->n_states;
    return fmi3OK;
}

/* --------------------------------------------------------- co-simulation */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    GUARD("fmi3EnterStepMode", ANY_STATE);
    if (inst->kind != KIND_CO_SIMULATION || !inst->event_mode_used)
        return unsupported(inst, "fmi3EnterStepMode",
                           NO_EVENT_MODE ": it is in Step Mode after fmi3ExitInitializationMode");
    if (!check_state(inst, "fmi3EnterStepMode", S_EVENT)) return fmi3Error;
    inst->core->state = ST_STEP_COMPLETE;
    inst->core->event_pending = 0;
    solver_reset(inst->memory, inst->model->n_states); /* the states may have jumped: a new history */
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    GUARD("fmi3GetOutputDerivatives", S_GET);
    (void)vr, (void)nvr, (void)orders, (void)values, (void)nValues;
    return unsupported(inst, "fmi3GetOutputDerivatives", "maxOutputDerivativeOrder = 0");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    GUARD("fmi3DoStep", S_STEP);
    LayerStatus status;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    status = do_step(inst, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
    if (lastSuccessfulTime) *lastSuccessfulTime = inst->core->time;
    if (status <= LAYER_WARNING && inst->core->event_pending) { /* stopped at an event (event mode) */
        if (eventHandlingNeeded) *eventHandlingNeeded = fmi3True;
        if (earlyReturn) *earlyReturn = inst->core->grid_steps > 0; /* before the step's end */
    }
    if (status == LAYER_DISCARD && inst->core->terminate) {
        /* The step completed and the model asks to end the simulation (FMI 3.0, 4.2.4). */
        if (terminateSimulation) *terminateSimulation = fmi3True;
        return fmi3OK;
    }
    return (fmi3Status)status;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    GUARD("fmi3ActivateModelPartition", ANY_STATE);
    if (!MODEL.n_clocks)
        return unsupported(inst, "fmi3ActivateModelPartition", "this FMU offers FMI 3.0 Co-Simulation only");
    return (fmi3Status)clock_activate(inst, "fmi3ActivateModelPartition", clockReference, activationTime);
}
