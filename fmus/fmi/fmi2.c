/* fmi2.c: every FMI 2.0 function (Co-Simulation and Model Exchange in one binary), a thin
 * interface over the shared layer (instance.c, step.c, derivative.c, log.c).
 *
 * Argument errors (unknown value reference, wrong type, value out of range, a
 * call in the wrong state) return fmi2Error and leave the instance unchanged,
 * so the caller may go on.  Computation errors (model equations failing,
 * non-finite results) return fmi2Error and put the instance into the Error
 * state, from which only fmi2Get*, fmi2SetFMUstate, fmi2Reset and
 * fmi2FreeInstance are allowed.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "instance.h"

#define GUARD(function, mask)                                         \
    Instance *inst = (Instance *)c;                                   \
    if (!inst) return fmi2Error;                                      \
    if (!check_state(inst, function, mask)) return fmi2Error

/* The layer's messages through the FMI 2.0 logger.  It treats the message as a printf format,
 * but loggers without varargs support show it verbatim: send it as the format, '%' doubled. */
static void emit(const Instance *inst, LayerStatus status, const char *category, const char *message) {
    char escaped[2048];
    size_t k = 0;
    for (const char *p = message; *p && k + 2 < sizeof escaped; p++) {
        if (*p == '%') escaped[k++] = '%';
        escaped[k++] = *p;
    }
    escaped[k] = '\0';
    ((fmi2CallbackLogger)inst->logger)(inst->env, inst->name, (fmi2Status)status, category, escaped);
}

/* ---------------------------------------------------------------- common */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    GUARD("fmi2SetDebugLogging", ANY_STATE);
    return (fmi2Status)set_debug_logging(inst, "fmi2SetDebugLogging", loggingOn, nCategories, categories);
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
    if (fmuType == fmi2CoSimulation && MODEL.me_only) { /* its description has no CoSimulation */
        if (logger)
            logger(env, name, fmi2Error, "logError", "fmi2Instantiate: %s offers Model Exchange only", MODEL.identifier);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, MODEL.guid) != 0) {
        if (logger)
            logger(env, name, fmi2Error, "logError", "fmi2Instantiate: GUID \"%s\" does not match %s's \"%s\"",
                   fmuGUID ? fmuGUID : "(null)", MODEL.identifier, MODEL.guid);
        return NULL;
    }
    inst = instance_new(name, fmuType == fmi2CoSimulation ? KIND_CO_SIMULATION : KIND_MODEL_EXCHANGE, 2, emit,
                        (void (*)(void))logger, env, loggingOn);
    if (!inst && logger) logger(env, name, fmi2Error, "logError", "fmi2Instantiate: out of memory");
    return inst;
}

void fmi2FreeInstance(fmi2Component c) { instance_free((Instance *)c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    GUARD("fmi2SetupExperiment", S_INST);
    (void)toleranceDefined;
    (void)tolerance;
    return setup_experiment(inst, "fmi2SetupExperiment", startTime, stopTimeDefined, stopTime) ? fmi2OK : fmi2Error;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    GUARD("fmi2EnterInitializationMode", S_INST);
    enter_initialization(inst);
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    GUARD("fmi2ExitInitializationMode", S_INIT);
    return (fmi2Status)exit_initialization(inst, "fmi2ExitInitializationMode");
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

#define T_MASK_REAL TYPE_MASK(T_REAL)
#define T_MASK_INTEGER (TYPE_MASK(T_INTEGER) | TYPE_MASK(T_SOLVER))
#define T_MASK_BOOLEAN TYPE_MASK(T_BOOLEAN)
#define T_MASK_STRING TYPE_MASK(T_STRING)

static double real_at(const void *values, size_t j) { return ((const fmi2Real *)values)[j]; }
static double integer_at(const void *values, size_t j) { return ((const fmi2Integer *)values)[j]; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    GUARD("fmi2GetReal", S_GET);
    if (!prepare_get(inst, "fmi2GetReal", vr, nvr, T_MASK_REAL, nvr)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = inst->reals[inst->model->variables[vr[i]].slot];
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    GUARD("fmi2GetInteger", S_GET);
    if (!prepare_get(inst, "fmi2GetInteger", vr, nvr, T_MASK_INTEGER, nvr)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = inst->integers[inst->model->variables[vr[i]].slot];
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    GUARD("fmi2GetBoolean", S_GET);
    if (!prepare_get(inst, "fmi2GetBoolean", vr, nvr, T_MASK_BOOLEAN, nvr)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = inst->booleans[inst->model->variables[vr[i]].slot];
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    GUARD("fmi2GetString", S_GET);
    if (!prepare_get(inst, "fmi2GetString", vr, nvr, T_MASK_STRING, nvr)) return fmi2Error; /* outputs refreshed */
    for (size_t i = 0; i < nvr; i++) value[i] = model_string(inst, inst->model->variables[vr[i]].slot);
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    GUARD("fmi2SetReal", S_SET);
    if (!check_access(inst, "fmi2SetReal", vr, nvr, T_MASK_REAL, nvr, 1, real_at, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) inst->reals[inst->model->variables[vr[i]].slot] = value[i];
    note_set(inst, vr, nvr);
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    GUARD("fmi2SetInteger", S_SET);
    if (!check_access(inst, "fmi2SetInteger", vr, nvr, T_MASK_INTEGER, nvr, 1, integer_at, value))
        return fmi2Error;
    for (size_t i = 0; i < nvr; i++) inst->integers[inst->model->variables[vr[i]].slot] = value[i];
    note_set(inst, vr, nvr);
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    GUARD("fmi2SetBoolean", S_SET);
    if (!check_access(inst, "fmi2SetBoolean", vr, nvr, T_MASK_BOOLEAN, nvr, 1, NULL, NULL)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) inst->booleans[inst->model->variables[vr[i]].slot] = value[i] != fmi2False;
    note_set(inst, vr, nvr);
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    GUARD("fmi2SetString", S_SET);
    if (!check_access(inst, "fmi2SetString", vr, nvr, T_MASK_STRING, nvr, 1, NULL, NULL)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (!value[i] || strlen(value[i]) >= STRING_CAPACITY) {
            layer_log(inst, LOG_ERROR, "fmi2SetString: variable %s: value is NULL or longer than %d bytes",
                      inst->model->variables[vr[i]].name, STRING_CAPACITY - 1);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++) model_set_string(inst, inst->model->variables[vr[i]].slot, value[i]);
    note_set(inst, vr, nvr);
    return fmi2OK;
}

/* ------------------------------------------------------------ FMU state */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    GUARD("fmi2GetFMUstate", ANY_STATE);
    return (fmi2Status)state_get(inst, "fmi2GetFMUstate", FMUstate);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    GUARD("fmi2SetFMUstate", ANY_STATE);
    return (fmi2Status)state_set(inst, "fmi2SetFMUstate", FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    GUARD("fmi2FreeFMUstate", ANY_STATE);
    state_free(FMUstate);
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    GUARD("fmi2SerializedFMUstateSize", ANY_STATE);
    return (fmi2Status)state_serialized_size(inst, FMUstate, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    GUARD("fmi2SerializeFMUstate", ANY_STATE);
    return (fmi2Status)state_serialize(inst, "fmi2SerializeFMUstate", FMUstate, (unsigned char *)serializedState,
                                       size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    GUARD("fmi2DeSerializeFMUstate", ANY_STATE);
    return (fmi2Status)state_deserialize(inst, "fmi2DeSerializeFMUstate", (const unsigned char *)serializedState,
                                         size, FMUstate);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    GUARD("fmi2GetDirectionalDerivative", S_INIT | S_STEP | S_EVENT | S_CONT | S_TERM);
    return (fmi2Status)directional_derivative(inst, "fmi2GetDirectionalDerivative", vUnknown_ref, nUnknown,
                                              vKnown_ref, nKnown, dvKnown, dvUnknown);
}

/* --------------------------------------------------------- co-simulation */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    GUARD("fmi2SetRealInputDerivatives", S_INST | S_INIT | S_STEP);
    if (inst->kind != KIND_CO_SIMULATION) {
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
    if (inst->kind != KIND_CO_SIMULATION) {
        layer_log(inst, LOG_ERROR, "fmi2DoStep: instance was created for Model Exchange");
        return fmi2Error;
    }
    return (fmi2Status)do_step(inst, "fmi2DoStep", currentCommunicationPoint, communicationStepSize);
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
    int needed = 0, changed = 0, terminate = 0;
    if (event_update(inst, "fmi2NewDiscreteStates", &needed, &changed, &terminate)) {
        inst->core->state = ST_ERROR;
        return inst->core->fatal ? fmi2Fatal : fmi2Error;
    }
    if (eventInfo) {
        eventInfo->newDiscreteStatesNeeded = needed && !terminate ? fmi2True : fmi2False;
        eventInfo->terminateSimulation = terminate ? fmi2True : fmi2False;
        eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
        eventInfo->valuesOfContinuousStatesChanged = changed ? fmi2True : fmi2False;
        eventInfo->nextEventTimeDefined = isfinite(inst->core->next_event_time) ? fmi2True : fmi2False;
        eventInfo->nextEventTime = isfinite(inst->core->next_event_time) ? inst->core->next_event_time : 0.0;
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
    int event = 0;
    if (inst->model->step_event) {
        gather_states(inst, inst->x);
        event = inst->model->step_event(inst, inst->core->time, inst->x) != 0;
    }
    if (enterEventMode) *enterEventMode = event ? fmi2True : fmi2False;
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
    if (ni != (size_t)inst->model->n_event_indicators) {
        layer_log(inst, LOG_ERROR, "fmi2GetEventIndicators: ni = %zu but the model has %d event indicators", ni,
                  inst->model->n_event_indicators);
        return fmi2Error;
    }
    if (event_indicators_now(inst, inst->z)) {
        layer_log(inst, LOG_ERROR, "fmi2GetEventIndicators: the model's event indicators failed at t = %.17g s%s",
                  inst->core->time, model_error_suffix(inst));
        inst->core->state = ST_ERROR;
        return inst->core->fatal ? fmi2Fatal : fmi2Error;
    }
    for (size_t i = 0; i < ni; i++) eventIndicators[i] = inst->z[i];
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
