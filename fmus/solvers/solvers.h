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

/* Dense LU with partial pivoting, row major n x n; returns 0, or 1 if singular. */
int lu_factor(int n, double *A, int *pivots);
void lu_solve(int n, const double *LU, const int *pivots, double *b);

#endif
