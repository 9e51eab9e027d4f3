/* solvers.c: the fixed-step methods of the paper's Table 1 plus classical RK4.
 *
 * Memory layout (doubles, all zero = no history):
 *   [0]            step h the history was built with
 *   [1]            number of valid history entries (0, 1 or 2)
 *   [2]            solver kind the history belongs to
 *   [3, 3+n)       f_{n-1}                (Adams-Bashforth)
 *   [3+n, 3+2n)    f_{n-2}                (Adams-Bashforth 3)
 *   [3+2n, 3+3n)   Delta_{n-1}            (semi-implicit midpoint)
 * No pointers: the caller copies and serializes it as part of the FMU state.
 *
 * Multistep history carries on across calls even if the model's inputs changed in
 * between (as in the paper's co-simulation, where each subsystem integrates on with
 * its own history); only a change of h or of the method restarts it.
 */
#include <float.h>
#include <math.h>
#include <stdlib.h>

#include "solvers.h"

enum { M_H = 0, M_COUNT = 1, M_KIND = 2, M_HEADER = 3 };

/* Relative change of h above which the history no longer fits the step. */
#define H_RESTART_TOL 1e-12

struct SolverWork {
    double *fn;    /* f(t_n, x_n) */
    double *k2;    /* RK4 stages */
    double *k3;
    double *k4;
    double *xs;    /* stage state, finite-difference probe */
    double *rhs;   /* right-hand side of the linear solve */
    double *jac;   /* n x n Jacobian, then I - hJ and its LU */
    int *pivots;
};

size_t solver_memory_size(int n)
{
    return (size_t)M_HEADER + 3 * (size_t)(n > 0 ? n : 0);
}

void solver_reset(double *memory, int n)
{
    size_t size = solver_memory_size(n);
    for (size_t i = 0; i < size; i++) {
        memory[i] = 0.0;
    }
}

SolverWork *solver_work_new(int n)
{
    if (n < 0) {
        return NULL;
    }
    SolverWork *w = calloc(1, sizeof *w);
    if (w == NULL) {
        return NULL;
    }
    size_t m = (size_t)(n > 0 ? n : 1);
    w->fn = calloc(m, sizeof(double));
    w->k2 = calloc(m, sizeof(double));
    w->k3 = calloc(m, sizeof(double));
    w->k4 = calloc(m, sizeof(double));
    w->xs = calloc(m, sizeof(double));
    w->rhs = calloc(m, sizeof(double));
    w->jac = calloc(m * m, sizeof(double));
    w->pivots = calloc(m, sizeof(int));
    if (!w->fn || !w->k2 || !w->k3 || !w->k4 || !w->xs || !w->rhs || !w->jac || !w->pivots) {
        solver_work_free(w);
        return NULL;
    }
    return w;
}

void solver_work_free(SolverWork *w)
{
    if (w == NULL) {
        return;
    }
    free(w->fn);
    free(w->k2);
    free(w->k3);
    free(w->k4);
    free(w->xs);
    free(w->rhs);
    free(w->jac);
    free(w->pivots);
    free(w);
}

/* Classical RK4 from (t, x) with k1 = f(t, x) already in w->fn. */
static int rk4_step(SolverWork *w, int n, RhsFn f, void *ctx, double t, double h, double *x)
{
    const double *k1 = w->fn;
    for (int i = 0; i < n; i++) {
        w->xs[i] = x[i] + 0.5 * h * k1[i];
    }
    if (f(ctx, t + 0.5 * h, w->xs, w->k2) != 0) {
        return 1;
    }
    for (int i = 0; i < n; i++) {
        w->xs[i] = x[i] + 0.5 * h * w->k2[i];
    }
    if (f(ctx, t + 0.5 * h, w->xs, w->k3) != 0) {
        return 1;
    }
    for (int i = 0; i < n; i++) {
        w->xs[i] = x[i] + h * w->k3[i];
    }
    if (f(ctx, t + h, w->xs, w->k4) != 0) {
        return 1;
    }
    for (int i = 0; i < n; i++) {
        x[i] += h / 6.0 * (k1[i] + 2.0 * w->k2[i] + 2.0 * w->k3[i] + w->k4[i]);
    }
    return 0;
}

/* J = df/dx at (t, x) by forward differences, with f(t, x) already in w->fn. */
static int fd_jacobian(SolverWork *w, int n, RhsFn f, void *ctx, double t, const double *x)
{
    const double sqrt_eps = sqrt(DBL_EPSILON);
    for (int j = 0; j < n; j++) {
        w->xs[j] = x[j];
    }
    for (int j = 0; j < n; j++) {
        double xj = x[j];
        double d = sqrt_eps * fmax(fabs(xj), 1.0);
        w->xs[j] = xj + d;
        d = w->xs[j] - xj; /* the increment actually represented */
        if (f(ctx, t, w->xs, w->k2) != 0) {
            return 1;
        }
        for (int i = 0; i < n; i++) {
            w->jac[i * n + j] = (w->k2[i] - w->fn[i]) / d;
        }
        w->xs[j] = xj;
    }
    return 0;
}

int solver_fd_jacobian(SolverWork *w, int n, RhsFn f, void *ctx, double t, const double *x)
{
    return fd_jacobian(w, n, f, ctx, t, x);
}

/* Factor I - hJ in w->jac, J at (t, x).  Returns 0, 1 (f or jac failed) or 2 (singular). */
static int factor_iteration_matrix(SolverWork *w, int n, RhsFn f, JacFn jac, void *ctx, double t, double h,
                                   const double *x)
{
    int status = jac != NULL ? (jac(ctx, t, x, w->jac) != 0) : fd_jacobian(w, n, f, ctx, t, x);
    if (status != 0) {
        return 1;
    }
    for (int i = 0; i < n; i++) {
        for (int j = 0; j < n; j++) {
            w->jac[i * n + j] *= -h;
        }
        w->jac[i * n + i] += 1.0;
    }
    return lu_factor(n, w->jac, w->pivots) != 0 ? 2 : 0;
}

/* Whether the stored history was built by the same method with the same step. */
static int history_fits(const double *memory, SolverKind kind, double h)
{
    double h_old = memory[M_H];
    return memory[M_COUNT] > 0.0 && memory[M_KIND] == (double)kind &&
           fabs(h - h_old) <= H_RESTART_TOL * fabs(h_old);
}

/* Adams-Bashforth of order `order` (2 or 3), started with RK4 steps until the
 * f history is full, so the start-up error stays below the method's order. */
static int adams_bashforth_step(int order, double *memory, SolverWork *w, int n, RhsFn f, void *ctx, double t,
                                double h, double *x)
{
    double *f1 = memory + M_HEADER;
    double *f2 = f1 + n;
    int count = (int)memory[M_COUNT];
    if (count >= order - 1) {
        for (int i = 0; i < n; i++) {
            double incr = order == 2 ? (3.0 * w->fn[i] - f1[i]) / 2.0
                                     : (23.0 * w->fn[i] - 16.0 * f1[i] + 5.0 * f2[i]) / 12.0;
            x[i] += h * incr;
        }
    } else if (rk4_step(w, n, f, ctx, t, h, x) != 0) {
        return 1;
    }
    for (int i = 0; i < n; i++) {
        f2[i] = f1[i];
        f1[i] = w->fn[i];
    }
    memory[M_COUNT] = count < 2 ? count + 1 : 2;
    return 0;
}

/* Semi-implicit Euler, Delta = [I - hJ]^-1 h f; or, once Delta_{n-1} exists, the
 * semi-implicit midpoint rule Delta_n = Delta_{n-1} + 2 [I - hJ]^-1 (h f - Delta_{n-1}). */
static int semi_implicit_step(int midpoint, double *memory, SolverWork *w, int n, RhsFn f, JacFn jac, void *ctx,
                              double t, double h, double *x)
{
    double *delta = memory + M_HEADER + 2 * n;
    int status = factor_iteration_matrix(w, n, f, jac, ctx, t, h, x);
    if (status != 0) {
        return status;
    }
    int two_step = midpoint && memory[M_COUNT] >= 1.0;
    for (int i = 0; i < n; i++) {
        w->rhs[i] = h * w->fn[i] - (two_step ? delta[i] : 0.0);
    }
    lu_solve(n, w->jac, w->pivots, w->rhs);
    for (int i = 0; i < n; i++) {
        delta[i] = two_step ? delta[i] + 2.0 * w->rhs[i] : w->rhs[i];
        x[i] += delta[i];
    }
    memory[M_COUNT] = 1.0;
    return 0;
}

int solver_step(SolverKind kind, double *memory, SolverWork *w, int n, RhsFn f, JacFn jac, void *ctx, double t,
                double h, double *x)
{
    if (n <= 0) {
        return 0;
    }
    if (!history_fits(memory, kind, h)) {
        solver_reset(memory, n);
    }
    memory[M_H] = h;
    memory[M_KIND] = (double)kind;
    if (f(ctx, t, x, w->fn) != 0) {
        return 1;
    }
    switch (kind) {
    case SOLVER_EULER:
        for (int i = 0; i < n; i++) {
            x[i] += h * w->fn[i];
        }
        return 0;
    case SOLVER_AB2:
        return adams_bashforth_step(2, memory, w, n, f, ctx, t, h, x);
    case SOLVER_AB3:
        return adams_bashforth_step(3, memory, w, n, f, ctx, t, h, x);
    case SOLVER_RK4:
        return rk4_step(w, n, f, ctx, t, h, x);
    case SOLVER_SEMI_IMPLICIT_EULER:
        return semi_implicit_step(0, memory, w, n, f, jac, ctx, t, h, x);
    case SOLVER_SEMI_IMPLICIT_MIDPOINT:
        return semi_implicit_step(1, memory, w, n, f, jac, ctx, t, h, x);
    }
    return 3;
}
