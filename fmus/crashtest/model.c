/* crashtest: a first-order lag that can be told to misbehave, for testing the master's isolation.
 *
 *   y' = -y + u
 *
 * Once t >= at_time, its derivative evaluation misbehaves according to `mode`:
 *   0 normal, 1 segmentation fault, 2 hang (busy loop), 3 abort(), 4 return an error (fmi2Error),
 *   5 report a fatal error (fmi2Fatal), 6 end the simulation (fmi2Discard with fmi2Terminated).
 * Every derivative evaluation burns `cost_us` microseconds of CPU, so that a scene of
 * crashtest components has a known, adjustable cost per step.
 * With `exclusive` set it behaves like a legacy FMU that holds a process-wide resource:
 * only one exclusive instance per process may initialise (the claim is an environment
 * variable holding the process id, so a forked child starts free).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "model.h"

enum { VR_SOLVER, VR_INTERNAL_STEP, VR_MODE, VR_AT_TIME, VR_COST_US, VR_EXCLUSIVE, VR_U, VR_Y, VR_DER_Y, N_VARIABLES };

enum { R_AT_TIME = R_MODEL_START, R_COST_US, R_U, R_Y, R_DER_Y, N_REALS };
enum { I_MODE = I_MODEL_START, N_INTEGERS };
enum { B_EXCLUSIVE, N_BOOLEANS };

enum { MODE_NORMAL, MODE_SEGFAULT, MODE_HANG, MODE_ABORT, MODE_ERROR, MODE_FATAL, MODE_TERMINATE };

static const Variable VARIABLES[N_VARIABLES] = {
    COMMON_VARIABLES(SOLVER_EULER, 0.0),
    {"mode", T_INTEGER, C_PARAMETER, V_FIXED, I_EXACT, I_MODE, MODE_NORMAL, NULL, 0, 6, NULL,
     "0 normal, 1 segfault, 2 hang, 3 abort, 4 error, 5 fatal, 6 terminate: what the derivative does once t >= at_time",
     NO_STATE, NULL},
    {"at_time", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_AT_TIME, 0.0, NULL, -INFINITY, INFINITY, "s",
     "time from which the derivative misbehaves", NO_STATE, NULL},
    {"cost_us", T_REAL, C_PARAMETER, V_FIXED, I_EXACT, R_COST_US, 0.0, NULL, 0, INFINITY, "us",
     "CPU time burnt by each derivative evaluation", NO_STATE, NULL},
    {"exclusive", T_BOOLEAN, C_PARAMETER, V_FIXED, I_EXACT, B_EXCLUSIVE, 0, NULL, 0, 1, NULL,
     "claim a process-wide resource: a second exclusive instance in the same process fails", NO_STATE, NULL},
    {"u", T_REAL, C_INPUT, V_CONTINUOUS, I_DEFAULT, R_U, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "input", NO_STATE, NULL},
    {"y", T_REAL, C_OUTPUT, V_CONTINUOUS, I_EXACT, R_Y, 1.0, NULL, -INFINITY, INFINITY, NULL,
     "state and output", NO_STATE, ""},
    {"der(y)", T_REAL, C_LOCAL, V_CONTINUOUS, I_CALCULATED, R_DER_Y, 0.0, NULL, -INFINITY, INFINITY, NULL,
     "derivative of y", VR_Y, NULL},
};

static const int STATE_SLOTS[] = {R_Y};
static const int DERIVATIVE_SLOTS[] = {R_DER_Y};

static double now_us(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e6 + (double)ts.tv_nsec * 1e-3;
}

/* Busy for `us` microseconds of wall time on an otherwise idle core: CPU work, not sleep. */
static void burn(double us) {
    if (us <= 0) return;
    const double end = now_us() + us;
    while (now_us() < end) {
    }
}

#define CLAIM "CRASHTEST_EXCLUSIVE_PID"

static ModelStatus initialize(Instance *inst) {
    if (!model_booleans(inst)[B_EXCLUSIVE]) return MODEL_OK;
    char pid[32];
    snprintf(pid, sizeof pid, "%ld", (long)getpid());
    const char *holder = getenv(CLAIM);
    if (holder != NULL && strcmp(holder, pid) == 0) {
        model_log(inst, "logError", "crashtest: another exclusive instance already lives in process %s", pid);
        return MODEL_ERROR;
    }
    setenv(CLAIM, pid, 1);
    return MODEL_OK;
}

static ModelStatus derivatives(Instance *inst, double t, const double *x, double *dx) {
    const double *r = model_reals(inst);
    burn(r[R_COST_US]);
    if (t >= r[R_AT_TIME]) {
        switch (model_integers(inst)[I_MODE]) {
        case MODE_SEGFAULT: {
            volatile int *volatile nowhere = NULL; /* volatile pointer and target: the write stays */
            *nowhere = 1;
            break;
        }
        case MODE_HANG: {
            volatile int forever = 1;
            while (forever) {
            }
            break;
        }
        case MODE_ABORT:
            abort();
        case MODE_ERROR:
            model_log(inst, "logError", "crashtest: error requested at t = %g", t);
            return MODEL_ERROR;
        case MODE_FATAL:
            model_log(inst, "logError", "crashtest: fatal error requested at t = %g", t);
            return MODEL_FATAL;
        case MODE_TERMINATE:
            dx[0] = -x[0] + r[R_U];
            return MODEL_TERMINATE;
        default:
            break;
        }
    }
    dx[0] = -x[0] + r[R_U];
    return MODEL_OK;
}

static ModelStatus jacobian(Instance *inst, double t, const double *x, double *J) {
    (void)inst;
    (void)t;
    (void)x;
    J[0] = -1.0;
    return MODEL_OK;
}

const ModelDef MODEL = {
    .identifier = "crashtest",
    .guid = "{4f1c2a7e-6b0d-4e8a-9c35-0d2b7e61c9a4}",
    .description = "First-order lag that segfaults, hangs, aborts or fails on request (isolation tests)",
    .variables = VARIABLES,
    .n_variables = N_VARIABLES,
    .n_reals = N_REALS,
    .n_integers = N_INTEGERS,
    .n_booleans = N_BOOLEANS,
    .n_strings = 0,
    .n_states = 1,
    .state_slots = STATE_SLOTS,
    .derivative_slots = DERIVATIVE_SLOTS,
    .initialize = initialize,
    .derivatives = derivatives,
    .jacobian = jacobian,
    .outputs = NULL,
};
