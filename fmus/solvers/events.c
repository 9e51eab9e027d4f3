/* events.c: fixed-step integration with the events of an FMI model (time, state and step events),
 * shared by the project's FMUs (Co-Simulation doStep) and the master's kernel (Model Exchange
 * components), so that both meet an event the same way.  See solvers.h. */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "solvers.h"

#define LOCATE_MAX_ITERATIONS 200 /* Illinois, then bisection from half of them on: ends well before */

struct EventWork {
    int n, n_z;
    double *z, *z_end, *z_a, *z_b, *z_try; /* n_z indicators: now, a step's end, the bracket, a trial */
    double *x0, *x_b;                       /* n states: the step's start, the bracket's right end */
    double *memory0;                        /* the history at the step's start */
};

EventWork *event_work_new(int n, int n_z)
{
    if (n < 0 || n_z < 0) {
        return NULL;
    }
    EventWork *e = calloc(1, sizeof *e);
    if (e == NULL) {
        return NULL;
    }
    size_t nz = (size_t)(n_z > 0 ? n_z : 1), nx = (size_t)(n > 0 ? n : 1);
    e->n = n;
    e->n_z = n_z;
    e->z = calloc(nz, sizeof(double));
    e->z_end = calloc(nz, sizeof(double));
    e->z_a = calloc(nz, sizeof(double));
    e->z_b = calloc(nz, sizeof(double));
    e->z_try = calloc(nz, sizeof(double));
    e->x0 = calloc(nx, sizeof(double));
    e->x_b = calloc(nx, sizeof(double));
    e->memory0 = calloc(solver_memory_size(n), sizeof(double));
    if (!e->z || !e->z_end || !e->z_a || !e->z_b || !e->z_try || !e->x0 || !e->x_b || !e->memory0) {
        event_work_free(e);
        return NULL;
    }
    return e;
}

void event_work_free(EventWork *e)
{
    if (e == NULL) {
        return;
    }
    free(e->z);
    free(e->z_end);
    free(e->z_a);
    free(e->z_b);
    free(e->z_try);
    free(e->x0);
    free(e->x_b);
    free(e->memory0);
    free(e);
}

/* Whether some indicator is in another domain (z > 0 or z <= 0) in za than in zb. */
static int domain_changed(int n_z, const double *za, const double *zb)
{
    for (int i = 0; i < n_z; i++) {
        if ((za[i] > 0.0) != (zb[i] > 0.0)) {
            return 1;
        }
    }
    return 0;
}

/* One step of size theta from the step's start (e->x0, e->memory0) into x, its indicators into z. */
static int trial_step(const OdeProblem *p, EventWork *e, double t, double theta, double *x, double *z)
{
    memcpy(p->memory, e->memory0, sizeof(double) * solver_memory_size(p->n));
    memcpy(x, e->x0, sizeof(double) * (size_t)p->n);
    int rc = solver_step(p->kind, p->memory, p->work, p->n, p->rhs, p->jac, p->ctx, t, theta, x);
    if (rc != 0) {
        return rc;
    }
    return p->indicators(p->ctx, t + theta, x, z) != 0;
}

/* The state event inside the step (t, t + h], whose end (x, e->z_end) is in another domain than its
 * start (e->x0, e->z): the bracket [a, b] of step sizes shrunk by Illinois to the tolerance; x and
 * *theta become the right end's. */
static int locate(const OdeProblem *p, EventWork *e, double t, double h, double *x, double *theta)
{
    const int n_z = p->n_z;
    const double tol = fmax(p->tolerance > 0.0 ? p->tolerance : EVENT_TOLERANCE, 8.0 * DBL_EPSILON * fabs(t + h));
    double a = 0.0, b = h, weight_a = 1.0, weight_b = 1.0;
    int kept = 0; /* -1: a was kept last time, 1: b was, 0: neither yet */
    memcpy(e->z_a, e->z, sizeof(double) * (size_t)n_z);
    memcpy(e->z_b, e->z_end, sizeof(double) * (size_t)n_z);
    memcpy(e->x_b, x, sizeof(double) * (size_t)p->n);
    for (int it = 0; b - a > tol && it < LOCATE_MAX_ITERATIONS; it++) {
        double next = 0.5 * (a + b);
        if (it < LOCATE_MAX_ITERATIONS / 2) { /* the earliest zero of the secants of the changing indicators */
            next = b;
            for (int i = 0; i < n_z; i++) {
                double za = weight_a * e->z_a[i], zb = weight_b * e->z_b[i];
                if ((e->z_a[i] > 0.0) != (e->z_b[i] > 0.0) && za != zb) {
                    next = fmin(next, a + (b - a) * za / (za - zb));
                }
            }
        }
        next = fmin(fmax(next, a + 0.5 * tol), b - 0.5 * tol);
        int rc = trial_step(p, e, t, next, x, e->z_try);
        if (rc != 0) {
            return rc;
        }
        if (domain_changed(n_z, e->z_a, e->z_try)) { /* the event lies in [a, next] */
            b = next;
            memcpy(e->z_b, e->z_try, sizeof(double) * (size_t)n_z);
            memcpy(e->x_b, x, sizeof(double) * (size_t)p->n);
            weight_b = 1.0;
            weight_a = kept == -1 ? 0.5 * weight_a : 1.0; /* Illinois: a kept twice, its value halved */
            kept = -1;
        } else {
            a = next;
            memcpy(e->z_a, e->z_try, sizeof(double) * (size_t)n_z);
            weight_a = 1.0;
            weight_b = kept == 1 ? 0.5 * weight_b : 1.0;
            kept = 1;
        }
    }
    memcpy(x, e->x_b, sizeof(double) * (size_t)p->n);
    memcpy(e->z_end, e->z_b, sizeof(double) * (size_t)n_z);
    *theta = b;
    return 0;
}

/* The event at t: the model's iteration, then the indicators anew and the history restarted. */
static int handle_event(const OdeProblem *p, EventWork *e, double t, double *x, double *next_time, long long *events)
{
    int stop = 0;
    if (p->event(p->ctx, t, x, next_time, &stop) != 0) {
        return 1;
    }
    if (stop == ODE_EVENT) { /* left to the caller, nothing done: x is the state at t */
        return ODE_EVENT;
    }
    (*events)++;
    solver_reset(p->memory, p->n);
    if (stop) {
        return ODE_STOP;
    }
    return p->n_z > 0 && p->indicators != NULL && p->indicators(p->ctx, t, x, e->z) != 0;
}

int ode_advance(const OdeProblem *p, EventWork *e, double t0, double h, long long steps, double t1, double *x,
                double *next_time, long long *events)
{
    return ode_advance_from(p, e, t0, h, steps, t1, t0, x, next_time, events, NULL);
}

int ode_advance_from(const OdeProblem *p, EventWork *e, double t0, double h, long long steps, double t1, double from,
                     double *x, double *next_time, long long *events, double *reached_time)
{
    const int watch = p->indicators != NULL && p->n_z > 0;
    double now = from;
    int rc, stop_after = 0;
    if (reached_time != NULL) {
        *reached_time = from;
    }
    if (watch && p->indicators(p->ctx, from, x, e->z) != 0) {
        return 1;
    }
    for (long long j = 0; j < steps; j++) {
        const double start = t0 + (double)j * h, end = j + 1 == steps ? t1 : t0 + (double)(j + 1) * h;
        while (now < end) {
            /* a pending time event inside the step cuts it */
            const int time_event = *next_time > now && *next_time <= end;
            const double target = time_event ? *next_time : end;
            const double size = now == start && target == end ? h : target - now;
            double reached = target;
            int event = time_event, state_event = 0;
            if (watch) {
                memcpy(e->x0, x, sizeof(double) * (size_t)p->n);
                memcpy(e->memory0, p->memory, sizeof(double) * solver_memory_size(p->n));
            }
            if ((rc = solver_step(p->kind, p->memory, p->work, p->n, p->rhs, p->jac, p->ctx, now, size, x)) != 0) {
                return rc;
            }
            if (watch) {
                if (p->indicators(p->ctx, target, x, e->z_end) != 0) {
                    return 1;
                }
                if (domain_changed(p->n_z, e->z, e->z_end)) {
                    double theta = size;
                    if ((rc = locate(p, e, now, size, x, &theta)) != 0) {
                        return rc;
                    }
                    state_event = 1;
                    if (theta < size) { /* before the target: the time event (if any) still pending */
                        reached = now + theta;
                        event = 0;
                    }
                }
                memcpy(e->z, e->z_end, sizeof(double) * (size_t)p->n_z);
            }
            now = reached;
            int step_event = 0, ends = 0;
            if (p->completed && p->completed(p->ctx, now, x, &step_event, &ends) != 0) {
                return 1;
            }
            stop_after |= ends; /* the steps go on to t1, then the simulation ends */
            if (reached_time != NULL) {
                *reached_time = now;
            }
            if ((event || state_event || step_event) && (rc = handle_event(p, e, now, x, next_time, events)) != 0) {
                return rc;
            }
        }
    }
    return stop_after ? ODE_STOP : 0;
}
