/* solvers.h: fixed-step ODE solvers of the shared core (the paper's Table 1 plus RK4).
 *
 * A solver advances x' = f(t, x) by one step h.  What a multistep method remembers
 * between steps lives in a plain array of solver_memory_size(n) doubles owned by the
 * caller, so that FMU state copies and serialization include it byte for byte.
 * Scratch space (stage vectors, Jacobian, LU) lives in SolverWork and is not state.
 */
#ifndef SOLVERS_H
#define SOLVERS_H

#include <stddef.h>

#include "model.h" /* SolverKind */

typedef int (*RhsFn)(void *ctx, double t, const double *x, double *dx);  /* 0: ok */
typedef int (*JacFn)(void *ctx, double t, const double *x, double *J);   /* row major df/dx; 0: ok */

typedef struct SolverWork SolverWork;

/* Number of doubles of solver memory for n states.  All zeros is a valid memory
 * without history.  Multistep history carries on across solver_step calls even
 * when the model's inputs changed in between (the paper's co-simulation); only a
 * change of h (beyond 1e-12 relative) or of the method restarts it. */
size_t solver_memory_size(int n);
/* Forget the history (multistep methods start up again on the next step). */
void solver_reset(double *memory, int n);

SolverWork *solver_work_new(int n);
void solver_work_free(SolverWork *w);

/* One step of `kind` from (t, x) to t + h, x updated in place.
 * jac may be NULL: semi-implicit methods then use forward finite differences.
 * A change of h restarts the multistep history.
 * x is only written when the step succeeds.  n <= 0 is a no-op.  No allocation.
 * Returns 0 on success, 1 if f or jac failed, 2 if the linear system is singular,
 * 3 if kind is not a SolverKind. */
int solver_step(SolverKind kind, double *memory, SolverWork *w, int n, RhsFn f, JacFn jac, void *ctx,
                double t, double h, double *x);

/* J = df/dx at (t, x) by forward differences into the work's Jacobian, for a JacFn that cannot give
 * its own (it is called with J = that matrix and f(t, x) evaluated): what jac = NULL gives. */
int solver_fd_jacobian(SolverWork *w, int n, RhsFn f, void *ctx, double t, const double *x);

/* -- events (events.c) ----------------------------------------------------------------------------
 * ode_advance integrates with the fixed steps above and handles the events of an FMI model:
 *  - time events: the next event time is met exactly (the step is cut there, the event handled, then
 *    the rest of the step to the grid point integrated);
 *  - state events: after each step the event indicators are compared with those at its start; an
 *    indicator that changed its domain (z > 0 against z <= 0, as FMI defines it) is located inside
 *    the step by regula falsi with the Illinois modification on the solver's step size theta:
 *    z(t + theta) after one step of size theta from the step's start (a multistep method, whose
 *    history fits another step size no more, takes its start-up step there: RK4 for AB2 and AB3,
 *    semi-implicit Euler for the midpoint rule), to an interval of `tolerance` seconds; the step is
 *    redone to the interval's right end (where the indicator has changed its domain) and the event
 *    handled there;
 *  - step events: `completed` after each step may ask for one.
 * After each event the multistep history restarts (solver_reset). */
typedef int (*IndicatorFn)(void *ctx, double t, const double *x, double *z); /* 0: ok */
/* After a completed step at (t, x): *event 1 asks for an event; *stop 1 ends the simulation after the
 * last step (ode_advance goes on to t1). 0: ok */
typedef int (*CompletedFn)(void *ctx, double t, const double *x, int *event, int *stop);
/* The event iteration at (t, x): may change x; writes the next time event (INFINITY: none) and *stop
 * (1: the model ends the simulation). 0: ok */
typedef int (*EventFn)(void *ctx, double t, double *x, double *next_time, int *stop);
/* EventFn's *stop = ODE_EVENT: the event is not handled here; ode_advance returns ODE_EVENT at once, x the
 * state at the event's time (an FMI 3 Co-Simulation FMU in event mode returns from doStep there). */

#define EVENT_TOLERANCE 1e-10 /* s: state events are located to this interval */

typedef struct {
    SolverKind kind;
    double *memory; /* solver_memory_size(n) */
    SolverWork *work;
    int n, n_z;
    RhsFn rhs;
    JacFn jac;         /* NULL: finite differences */
    IndicatorFn indicators; /* NULL or n_z = 0: no state events */
    CompletedFn completed;  /* NULL: no step events */
    EventFn event;
    void *ctx;
    double tolerance;  /* s, the located state event's interval; <= 0: EVENT_TOLERANCE */
} OdeProblem;

typedef struct EventWork EventWork;
EventWork *event_work_new(int n, int n_z);
void event_work_free(EventWork *e);

/* What ode_advance returns: 0, the solver's codes 1 (f, jac, the indicators, completed or the event
 * failed), 2 (singular), 3 (bad kind), or ODE_STOP: the model ends the simulation (an event's: at once, x at that time; completed's: at t1). */
enum { ODE_STOP = 4, ODE_EVENT = 5 };

/* Integrate x from t0 to t1 in `steps` steps of size h (t1 = t0 + steps h but for rounding): step j from
 * t0 + j h, the last ending at t1 exactly; without events exactly what solver_step alone gives,
 * handling the events on the way; *next_time: the pending time event (INFINITY: none), updated by the
 * events; *events counts them. */
int ode_advance(const OdeProblem *p, EventWork *e, double t0, double h, long long steps, double t1, double *x,
                double *next_time, long long *events);
/* ode_advance on the same grid of steps, begun at time `from` (t0 <= from < t1, x the state there): a step
 * cut by `from` is taken from there to its end (an FMI 3 FMU completing a step it returned early from).
 * *reached_time (NULL: not wanted): the time x belongs to on return (the event's on ODE_EVENT). */
int ode_advance_from(const OdeProblem *p, EventWork *e, double t0, double h, long long steps, double t1, double from,
                     double *x, double *next_time, long long *events, double *reached_time);

/* Dense LU with partial pivoting, row major n x n; returns 0, or 1 if singular. */
int lu_factor(int n, double *A, int *pivots);
void lu_solve(int n, const double *LU, const int *pivots, double *b);

#endif
