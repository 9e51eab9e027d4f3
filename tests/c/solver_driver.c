/* solver_driver.c: runs fmus/solvers on plain C right-hand sides, for tests/test_solvers.py.
 *
 *   solver_driver ode <kind> <h> <steps> <omega> <jac 0|1>
 *       the system of fmus/nonlinear (a = 1) from x(0) = (1, 0);
 *       prints the final state, one value per line (%.17g)
 *   solver_driver lu <n>
 *       reads an n x n matrix (row major) and a right-hand side from stdin,
 *       prints the solution of A x = b, or "singular"
 *   solver_driver restart
 *       checks that a change of h restarts AB3 and that memory is plain data
 *       (copying it mid-run reproduces the run), prints "ok" or what failed
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "solvers.h"

typedef struct {
    double param;
    long evaluations;
} Ctx;

static int dahlquist_f(void *ctx, double t, const double *x, double *dx)
{
    (void)t;
    dx[0] = ((Ctx *)ctx)->param * x[0];
    ((Ctx *)ctx)->evaluations++;
    return 0;
}

static int dahlquist_j(void *ctx, double t, const double *x, double *J)
{
    (void)t;
    (void)x;
    J[0] = ((Ctx *)ctx)->param;
    return 0;
}

/* x' = -x s - w y, y' = -y s + w x, s = x^2 + y^2, w = omega (1 + t). */
static int nonlinear_f(void *ctx, double t, const double *x, double *dx)
{
    double w = ((Ctx *)ctx)->param * (1.0 + t);
    double s = x[0] * x[0] + x[1] * x[1];
    dx[0] = -x[0] * s - w * x[1];
    dx[1] = -x[1] * s + w * x[0];
    ((Ctx *)ctx)->evaluations++;
    return 0;
}

static int nonlinear_j(void *ctx, double t, const double *x, double *J)
{
    double w = ((Ctx *)ctx)->param * (1.0 + t);
    double s = x[0] * x[0] + x[1] * x[1];
    J[0] = -s - 2.0 * x[0] * x[0];
    J[1] = -2.0 * x[0] * x[1] - w;
    J[2] = -2.0 * x[0] * x[1] + w;
    J[3] = -s - 2.0 * x[1] * x[1];
    return 0;
}

static int run_ode(int argc, char **argv)
{
    if (argc != 7) {
        fprintf(stderr, "usage: ode <kind> <h> <steps> <omega> <jac 0|1>\n");
        return 2;
    }
    SolverKind kind = (SolverKind)atoi(argv[2]);
    double h = atof(argv[3]);
    long steps = atol(argv[4]);
    Ctx ctx = {atof(argv[5]), 0};
    JacFn j = atoi(argv[6]) ? nonlinear_j : NULL;
    double x[2] = {1.0, 0.0};
    double *memory = calloc(solver_memory_size(2), sizeof(double));
    SolverWork *w = solver_work_new(2);
    for (long k = 0; k < steps; k++) {
        int status = solver_step(kind, memory, w, 2, nonlinear_f, j, &ctx, (double)k * h, h, x);
        if (status != 0) {
            printf("error %d\n", status);
            return 0;
        }
    }
    printf("%.17g\n%.17g\n", x[0], x[1]);
    solver_work_free(w);
    free(memory);
    return 0;
}

static int run_lu(int argc, char **argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: lu <n>\n");
        return 2;
    }
    int n = atoi(argv[2]);
    double *A = malloc(sizeof(double) * (size_t)(n * n));
    double *b = malloc(sizeof(double) * (size_t)n);
    int *piv = malloc(sizeof(int) * (size_t)n);
    for (int i = 0; i < n * n; i++) {
        if (scanf("%lf", &A[i]) != 1) {
            return 2;
        }
    }
    for (int i = 0; i < n; i++) {
        if (scanf("%lf", &b[i]) != 1) {
            return 2;
        }
    }
    if (lu_factor(n, A, piv) != 0) {
        printf("singular\n");
    } else {
        lu_solve(n, A, piv, b);
        for (int i = 0; i < n; i++) {
            printf("%.17g\n", b[i]);
        }
    }
    free(A);
    free(b);
    free(piv);
    return 0;
}

/* Runs AB3 on the nonlinear problem for `steps` steps of h from x, t. */
static void advance(double *memory, SolverWork *w, Ctx *ctx, double *t, double h, int steps, double *x)
{
    for (int k = 0; k < steps; k++) {
        solver_step(SOLVER_AB3, memory, w, 2, nonlinear_f, NULL, ctx, *t, h, x);
        *t += h;
    }
}

static int run_restart(void)
{
    size_t m = solver_memory_size(2);
    double *mem = calloc(m, sizeof(double));
    double *copy = calloc(m, sizeof(double));
    SolverWork *w = solver_work_new(2);
    Ctx ctx = {1.0, 0};
    double x[2] = {1.0, 0.0}, t = 0.0;

    /* AB3 uses 4 evaluations in each of its 2 RK4 start-up steps, then 1 per step. */
    advance(mem, w, &ctx, &t, 0.01, 5, x);
    if (ctx.evaluations != 4 + 4 + 1 + 1 + 1) {
        printf("start-up used %ld evaluations, expected 11\n", ctx.evaluations);
        return 0;
    }
    /* Same h within 1e-12 relative: history carries on (1 evaluation). */
    ctx.evaluations = 0;
    advance(mem, w, &ctx, &t, 0.01 * (1.0 + 1e-14), 1, x);
    if (ctx.evaluations != 1) {
        printf("tiny change of h restarted the history\n");
        return 0;
    }
    /* A real change of h: RK4 start-up again (4 evaluations). */
    ctx.evaluations = 0;
    advance(mem, w, &ctx, &t, 0.02, 1, x);
    if (ctx.evaluations != 4) {
        printf("change of h did not restart the history\n");
        return 0;
    }
    /* Memory is plain data: a copy continues the run bit for bit. */
    double x_copy[2] = {x[0], x[1]}, t_copy = t;
    memcpy(copy, mem, m * sizeof(double));
    advance(mem, w, &ctx, &t, 0.02, 7, x);
    SolverWork *w2 = solver_work_new(2);
    advance(copy, w2, &ctx, &t_copy, 0.02, 7, x_copy);
    if (memcmp(x, x_copy, sizeof x) != 0) {
        printf("copied memory did not reproduce the run\n");
        return 0;
    }
    /* Unknown kind and singular I - hJ are reported. */
    double y[1] = {1.0};
    Ctx c2 = {2.0, 0};
    double *m1 = calloc(solver_memory_size(1), sizeof(double));
    SolverWork *w1 = solver_work_new(1);
    if (solver_step((SolverKind)99, m1, w1, 1, dahlquist_f, NULL, &c2, 0.0, 0.1, y) != 3) {
        printf("unknown kind not reported\n");
        return 0;
    }
    if (solver_step(SOLVER_SEMI_IMPLICIT_EULER, m1, w1, 1, dahlquist_f, dahlquist_j, &c2, 0.0, 0.5, y) != 2 ||
        y[0] != 1.0) {
        printf("singular I - hJ not reported, or x changed\n");
        return 0;
    }
    printf("ok\n");
    solver_work_free(w);
    solver_work_free(w2);
    solver_work_free(w1);
    free(mem);
    free(copy);
    free(m1);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc >= 2 && strcmp(argv[1], "ode") == 0) {
        return run_ode(argc, argv);
    }
    if (argc >= 2 && strcmp(argv[1], "lu") == 0) {
        return run_lu(argc, argv);
    }
    if (argc >= 2 && strcmp(argv[1], "restart") == 0) {
        return run_restart();
    }
    fprintf(stderr, "usage: solver_driver ode|lu|restart ...\n");
    return 2;
}
