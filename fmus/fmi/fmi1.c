/* fmi1.c: the FMI 1.0 Co-Simulation functions (stand-alone slave), a thin interface over the
 * shared layer (instance.c, step.c, log.c).
 *
 * FMI 1.0 prefixes every function with the model identifier: the build passes
 * -DMODEL_IDENTIFIER=<name>.  The layer's state machine maps onto FMI 1.0 as
 * fmiInstantiateSlave -> Instantiated, fmiInitializeSlave -> (initialization) -> StepComplete,
 * fmiTerminateSlave -> Terminated; fmiResetSlave returns to Instantiated.  Errors behave as in
 * fmi2.c: argument errors leave the instance unchanged, computation errors put it into Error.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi1Functions.h"
#include "instance.h"

#ifndef MODEL_IDENTIFIER
#error "compile with -DMODEL_IDENTIFIER=<model identifier>"
#endif
#define FMI1_CAT2(a, b) a##_##b
#define FMI1_CAT(a, b) FMI1_CAT2(a, b)
#define FMI1(name) FMI1_CAT(MODEL_IDENTIFIER, name) /* FMI1(fmiDoStep) -> <identifier>_fmiDoStep */

#define GUARD(function, mask)                                         \
    Instance *inst = (Instance *)c;                                   \
    if (!inst) return fmi1Error;                                      \
    if (!check_state(inst, function, mask)) return fmi1Error

/* The layer's messages through the FMI 1.0 logger (a printf format: '%' doubled). */
static void emit(const Instance *inst, LayerStatus status, const char *category, const char *message) {
    char escaped[2048];
    size_t k = 0;
    for (const char *p = message; *p && k + 2 < sizeof escaped; p++) {
        if (*p == '%') escaped[k++] = '%';
        escaped[k++] = *p;
    }
    escaped[k] = '\0';
    ((fmi1CallbackLogger)inst->logger)((fmi1Component)inst, inst->name, (fmi1Status)status, category, escaped);
}

/* ---------------------------------------------------------------- common */

const char *FMI1(fmiGetTypesPlatform)(void) { return "standard32"; }
const char *FMI1(fmiGetVersion)(void) { return "1.0"; }

fmi1Status FMI1(fmiSetDebugLogging)(fmi1Component c, fmi1Boolean loggingOn) {
    GUARD("fmiSetDebugLogging", ANY_STATE);
    return (fmi1Status)set_debug_logging(inst, "fmiSetDebugLogging", loggingOn, 0, NULL);
}

fmi1Component FMI1(fmiInstantiateSlave)(fmi1String instanceName, fmi1String fmuGUID, fmi1String fmuLocation,
                                        fmi1String mimeType, fmi1Real timeout, fmi1Boolean visible,
                                        fmi1Boolean interactive, fmi1CallbackFunctions functions,
                                        fmi1Boolean loggingOn) {
    const char *name = instanceName ? instanceName : "";
    Instance *inst;
    (void)fmuLocation, (void)mimeType, (void)timeout, (void)visible, (void)interactive;
    if (!fmuGUID || strcmp(fmuGUID, MODEL.guid) != 0) {
        if (functions.logger)
            functions.logger(NULL, name, fmi1Error, "logError",
                             "fmiInstantiateSlave: GUID \"%s\" does not match %s's \"%s\"",
                             fmuGUID ? fmuGUID : "(null)", MODEL.identifier, MODEL.guid);
        return NULL;
    }
    inst = instance_new(name, KIND_CO_SIMULATION, 1, emit, (void (*)(void))functions.logger, NULL, loggingOn);
    if (!inst && functions.logger)
        functions.logger(NULL, name, fmi1Error, "logError", "fmiInstantiateSlave: out of memory");
    return inst;
}

fmi1Status FMI1(fmiInitializeSlave)(fmi1Component c, fmi1Real tStart, fmi1Boolean StopTimeDefined,
                                    fmi1Real tStop) {
    GUARD("fmiInitializeSlave", S_INST);
    if (!setup_experiment(inst, "fmiInitializeSlave", tStart, StopTimeDefined, tStop)) return fmi1Error;
    enter_initialization(inst);
    return (fmi1Status)exit_initialization(inst, "fmiInitializeSlave");
}

fmi1Status FMI1(fmiTerminateSlave)(fmi1Component c) {
    GUARD("fmiTerminateSlave", S_STEP);
    inst->core->state = ST_TERMINATED;
    return fmi1OK;
}

fmi1Status FMI1(fmiResetSlave)(fmi1Component c) {
    GUARD("fmiResetSlave", ANY_STATE);
    instance_reset(inst);
    return fmi1OK;
}

void FMI1(fmiFreeSlaveInstance)(fmi1Component c) { instance_free((Instance *)c); }

/* ------------------------------------------------------- get/set values */

#define T_MASK_REAL TYPE_MASK(T_REAL)
#define T_MASK_INTEGER (TYPE_MASK(T_INTEGER) | TYPE_MASK(T_SOLVER))
#define T_MASK_BOOLEAN TYPE_MASK(T_BOOLEAN)
#define T_MASK_STRING TYPE_MASK(T_STRING)

/* FMI 1.0 importers (libcosim among them) read start values between fmiInstantiateSlave and
 * fmiInitializeSlave: there the stored values are returned as they are, nothing is evaluated. */
#define S_GET1 (S_GET | S_INST)
static int get_ok(Instance *inst, const char *function, const fmi1ValueReference vr[], size_t nvr,
                  unsigned types) {
    if (inst->core->state == ST_INSTANTIATED)
        return check_access(inst, function, vr, nvr, types, nvr, 0, NULL, NULL);
    return prepare_get(inst, function, vr, nvr, types, nvr);
}

static double real_at(const void *values, size_t j) { return ((const fmi1Real *)values)[j]; }
static double integer_at(const void *values, size_t j) { return ((const fmi1Integer *)values)[j]; }

fmi1Status FMI1(fmiGetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1Real value[]) {
    GUARD("fmiGetReal", S_GET1);
    if (!get_ok(inst, "fmiGetReal", vr, nvr, T_MASK_REAL)) return fmi1Error;
    for (size_t i = 0; i < nvr; i++) value[i] = inst->reals[inst->model->variables[vr[i]].slot];
    return fmi1OK;
}

fmi1Status FMI1(fmiGetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1Integer value[]) {
    GUARD("fmiGetInteger", S_GET1);
    if (!get_ok(inst, "fmiGetInteger", vr, nvr, T_MASK_INTEGER)) return fmi1Error;
    for (size_t i = 0; i < nvr; i++) value[i] = inst->integers[inst->model->variables[vr[i]].slot];
    return fmi1OK;
}

fmi1Status FMI1(fmiGetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1Boolean value[]) {
    GUARD("fmiGetBoolean", S_GET1);
    if (!get_ok(inst, "fmiGetBoolean", vr, nvr, T_MASK_BOOLEAN)) return fmi1Error;
    for (size_t i = 0; i < nvr; i++)
        value[i] = inst->booleans[inst->model->variables[vr[i]].slot] ? fmi1True : fmi1False;
    return fmi1OK;
}

fmi1Status FMI1(fmiGetString)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1String value[]) {
    GUARD("fmiGetString", S_GET1);
    if (!get_ok(inst, "fmiGetString", vr, nvr, T_MASK_STRING)) return fmi1Error;
    for (size_t i = 0; i < nvr; i++) value[i] = model_string(inst, inst->model->variables[vr[i]].slot);
    return fmi1OK;
}

fmi1Status FMI1(fmiSetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, const fmi1Real value[]) {
    GUARD("fmiSetReal", S_SET);
    if (!check_access(inst, "fmiSetReal", vr, nvr, T_MASK_REAL, nvr, 1, real_at, value)) return fmi1Error;
    for (size_t i = 0; i < nvr; i++) inst->reals[inst->model->variables[vr[i]].slot] = value[i];
    note_set(inst, vr, nvr);
    return fmi1OK;
}

fmi1Status FMI1(fmiSetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                               const fmi1Integer value[]) {
    GUARD("fmiSetInteger", S_SET);
    if (!check_access(inst, "fmiSetInteger", vr, nvr, T_MASK_INTEGER, nvr, 1, integer_at, value)) return fmi1Error;
    for (size_t i = 0; i < nvr; i++) inst->integers[inst->model->variables[vr[i]].slot] = value[i];
    note_set(inst, vr, nvr);
    return fmi1OK;
}

fmi1Status FMI1(fmiSetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                               const fmi1Boolean value[]) {
    GUARD("fmiSetBoolean", S_SET);
    if (!check_access(inst, "fmiSetBoolean", vr, nvr, T_MASK_BOOLEAN, nvr, 1, NULL, NULL)) return fmi1Error;
    for (size_t i = 0; i < nvr; i++) inst->booleans[inst->model->variables[vr[i]].slot] = value[i] != fmi1False;
    note_set(inst, vr, nvr);
    return fmi1OK;
}

fmi1Status FMI1(fmiSetString)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                              const fmi1String value[]) {
    GUARD("fmiSetString", S_SET);
    if (!check_access(inst, "fmiSetString", vr, nvr, T_MASK_STRING, nvr, 1, NULL, NULL)) return fmi1Error;
    for (size_t i = 0; i < nvr; i++) {
        if (!value[i] || strlen(value[i]) >= STRING_CAPACITY) {
            layer_log(inst, LOG_ERROR, "fmiSetString: variable %s: value is NULL or longer than %d bytes",
                      inst->model->variables[vr[i]].name, STRING_CAPACITY - 1);
            return fmi1Error;
        }
    }
    for (size_t i = 0; i < nvr; i++) model_set_string(inst, inst->model->variables[vr[i]].slot, value[i]);
    note_set(inst, vr, nvr);
    return fmi1OK;
}

/* --------------------------------------------------------- co-simulation */

fmi1Status FMI1(fmiSetRealInputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                            const fmi1Integer order[], const fmi1Real value[]) {
    GUARD("fmiSetRealInputDerivatives", S_INST | S_STEP);
    for (size_t i = 0; i < nvr; i++) {
        const Variable *v = lookup(inst, "fmiSetRealInputDerivatives", vr[i], T_MASK_REAL);
        if (!v) return fmi1Error;
        if (inst->input_index[vr[i]] < 0) {
            layer_log(inst, LOG_ERROR, "fmiSetRealInputDerivatives: variable %s is not an input", v->name);
            return fmi1Error;
        }
        if (order[i] < 1 || order[i] > MAX_INPUT_ORDER || !isfinite(value[i])) {
            layer_log(inst, LOG_ERROR, "fmiSetRealInputDerivatives: variable %s: order %d not in 1..%d or "
                      "derivative %g not finite", v->name, (int)order[i], MAX_INPUT_ORDER, value[i]);
            return fmi1Error;
        }
    }
    for (size_t i = 0; i < nvr; i++)
        inst->input_derivs[(size_t)inst->input_index[vr[i]] * MAX_INPUT_ORDER + (size_t)(order[i] - 1)] = value[i];
    inst->core->have_input_derivatives = 1;
    return fmi1OK;
}

fmi1Status FMI1(fmiGetRealOutputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                             const fmi1Integer order[], fmi1Real value[]) {
    GUARD("fmiGetRealOutputDerivatives", S_GET);
    (void)vr, (void)nvr, (void)order, (void)value;
    layer_log(inst, LOG_ERROR, "fmiGetRealOutputDerivatives: not supported (maxOutputDerivativeOrder = 0)");
    return fmi1Error;
}

fmi1Status FMI1(fmiDoStep)(fmi1Component c, fmi1Real currentCommunicationPoint, fmi1Real communicationStepSize,
                           fmi1Boolean newStep) {
    GUARD("fmiDoStep", S_STEP);
    (void)newStep; /* no state rollback in FMI 1.0: every step is a new one */
    return (fmi1Status)do_step(inst, "fmiDoStep", currentCommunicationPoint, communicationStepSize);
}

fmi1Status FMI1(fmiCancelStep)(fmi1Component c) {
    GUARD("fmiCancelStep", ANY_STATE);
    layer_log(inst, LOG_ERROR, "fmiCancelStep: steps are synchronous, nothing to cancel");
    return fmi1Error;
}

static fmi1Status no_status(Instance *inst, const char *function) {
    layer_log(inst, LOG_ERROR, "%s: not supported (steps are synchronous)", function);
    return fmi1Error;
}

fmi1Status FMI1(fmiGetStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Status *value) {
    GUARD("fmiGetStatus", ANY_STATE);
    (void)s, (void)value;
    return no_status(inst, "fmiGetStatus");
}

fmi1Status FMI1(fmiGetRealStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Real *value) {
    GUARD("fmiGetRealStatus", ANY_STATE);
    if (s == fmi1LastSuccessfulTime && value) {
        *value = inst->core->time;
        return fmi1OK;
    }
    return no_status(inst, "fmiGetRealStatus");
}

fmi1Status FMI1(fmiGetIntegerStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Integer *value) {
    GUARD("fmiGetIntegerStatus", ANY_STATE);
    (void)s, (void)value;
    return no_status(inst, "fmiGetIntegerStatus");
}

fmi1Status FMI1(fmiGetBooleanStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Boolean *value) {
    GUARD("fmiGetBooleanStatus", ANY_STATE);
    (void)s, (void)value;
    return no_status(inst, "fmiGetBooleanStatus");
}

fmi1Status FMI1(fmiGetStringStatus)(fmi1Component c, const fmi1StatusKind s, fmi1String *value) {
    GUARD("fmiGetStringStatus", ANY_STATE);
    (void)s, (void)value;
    return no_status(inst, "fmiGetStringStatus");
}
