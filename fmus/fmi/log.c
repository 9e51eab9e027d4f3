/* log.c: logging through the importer's callback (via the interface's emit), the
 * state-machine guard and SetDebugLogging. */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "instance.h"

const char *const LOG_CATEGORY_NAMES[LOG_N_CATEGORIES] = {"logError", "logWarning", "logInfo", "logDebug"};
/* For modelDescription.xml (printed by describe.c). */
const char *const LOG_CATEGORY_DESCRIPTIONS[LOG_N_CATEGORIES] = {
    "errors: failed calls, bad arguments, non-finite results", "warnings", "information", "debugging details"};

static const LayerStatus CATEGORY_STATUS[LOG_N_CATEGORIES] = {LAYER_ERROR, LAYER_WARNING, LAYER_OK, LAYER_OK};

static void vlog(Instance *inst, int category, const char *fmt, va_list ap) {
    char message[1024];
    if (!inst || !inst->logger || !inst->emit) return;
    /* Errors always reach the logger; other categories only when enabled. */
    if (category != LOG_ERROR && !(inst->log_mask & (1u << category))) return;
    vsnprintf(message, sizeof message, fmt, ap);
    inst->emit(inst, CATEGORY_STATUS[category], LOG_CATEGORY_NAMES[category], message);
}

void layer_log(Instance *inst, int category, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vlog(inst, category, fmt, ap);
    va_end(ap);
}

void model_log(Instance *inst, const char *category, const char *fmt, ...) {
    int c = LOG_INFO;
    va_list ap;
    for (int i = 0; i < LOG_N_CATEGORIES; i++)
        if (category && strcmp(category, LOG_CATEGORY_NAMES[i]) == 0) c = i;
    va_start(ap, fmt);
    vlog(inst, c, fmt, ap);
    va_end(ap);
    if (c == LOG_ERROR && inst) { /* kept so that the layer's report names the cause too */
        va_start(ap, fmt);
        inst->model_error[0] = ':', inst->model_error[1] = ' ';
        vsnprintf(inst->model_error + 2, sizeof inst->model_error - 2, fmt, ap);
        va_end(ap);
    }
}

const char *model_error_suffix(Instance *inst) {
    memcpy(inst->error_suffix, inst->model_error, sizeof inst->error_suffix);
    inst->model_error[0] = '\0';
    return inst->error_suffix;
}

const char *state_name(const Instance *inst, int state) {
    static const char *const names[ST_COUNT] = {
        "Instantiated", "InitializationMode", "StepComplete", "EventMode", "ContinuousTimeMode",
        "Terminated",   "Error"};
    if (state == ST_STEP_COMPLETE && inst->fmi_version == 3) return "StepMode";
    return (state >= 0 && state < ST_COUNT) ? names[state] : "unknown";
}

int check_state(Instance *inst, const char *function, unsigned allowed_mask) {
    if (inst->in_intermediate_update && strcmp(function, "fmi3SetFloat64") != 0) { /* inside the callback */
        layer_log(inst, LOG_ERROR, "%s: not allowed in Intermediate Update Mode (fmi3SetFloat64 is)", function);
        return 0;
    }
    if (allowed_mask & MASK(inst->core->state)) return 1;
    layer_log(inst, LOG_ERROR, "%s: not allowed in state %s", function, state_name(inst, inst->core->state));
    return 0;
}

LayerStatus set_debug_logging(Instance *inst, const char *function, int on, size_t n,
                              const char *const categories[]) {
    unsigned mask = inst->log_mask;
    if (n == 0) {
        mask = on ? (1u << LOG_N_CATEGORIES) - 1u : 0u;
    } else {
        for (size_t i = 0; i < n; i++) {
            int found = -1;
            for (int k = 0; k < LOG_N_CATEGORIES; k++)
                if (categories[i] && strcmp(categories[i], LOG_CATEGORY_NAMES[k]) == 0) found = k;
            if (found < 0) {
                layer_log(inst, LOG_ERROR, "%s: unknown log category \"%s\"", function,
                          categories[i] ? categories[i] : "(null)");
                return LAYER_ERROR;
            }
            mask = on ? (mask | (1u << found)) : (mask & ~(1u << found));
        }
    }
    inst->log_mask = mask;
    return LAYER_OK;
}
