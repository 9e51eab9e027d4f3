/* log.c: logging through the FMI callback and the state-machine guard. */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "instance.h"

const char *const LOG_CATEGORY_NAMES[LOG_N_CATEGORIES] = {"logError", "logWarning", "logInfo", "logDebug"};
/* For modelDescription.xml (printed by describe.c). */
const char *const LOG_CATEGORY_DESCRIPTIONS[LOG_N_CATEGORIES] = {
    "errors: failed calls, bad arguments, non-finite results", "warnings", "information", "debugging details"};

static const fmi2Status CATEGORY_STATUS[LOG_N_CATEGORIES] = {fmi2Error, fmi2Warning, fmi2OK, fmi2OK};

static void vlog(Instance *inst, int category, const char *fmt, va_list ap) {
    char message[1024], escaped[2048];
    size_t k = 0;
    if (!inst || !inst->logger) return;
    /* Errors always reach the logger; other categories only when enabled. */
    if (category != LOG_ERROR && !(inst->log_mask & (1u << category))) return;
    vsnprintf(message, sizeof message, fmt, ap);
    /* The logger treats the message as a printf format, but loggers without
     * varargs support show it verbatim: send it as the format, '%' doubled. */
    for (const char *p = message; *p && k + 2 < sizeof escaped; p++) {
        if (*p == '%') escaped[k++] = '%';
        escaped[k++] = *p;
    }
    escaped[k] = '\0';
    inst->logger(inst->env, inst->name, CATEGORY_STATUS[category], LOG_CATEGORY_NAMES[category], escaped);
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

const char *state_name(int state) {
    static const char *const names[ST_COUNT] = {
        "Instantiated", "InitializationMode", "StepComplete", "EventMode", "ContinuousTimeMode",
        "Terminated",   "Error"};
    return (state >= 0 && state < ST_COUNT) ? names[state] : "unknown";
}

int check_state(Instance *inst, const char *function, unsigned allowed_mask) {
    if (allowed_mask & MASK(inst->core->state)) return 1;
    layer_log(inst, LOG_ERROR, "%s: not allowed in state %s", function, state_name(inst->core->state));
    return 0;
}
