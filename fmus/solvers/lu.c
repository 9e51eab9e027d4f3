/* lu.c: dense LU factorization with partial pivoting (Doolittle, row major, in place).
 *
 * After lu_factor, A holds U on and above the diagonal and the multipliers of L
 * (unit diagonal) below it; pivots[k] is the row swapped with row k at step k.
 */
#include <math.h>

#include "solvers.h"

int lu_factor(int n, double *A, int *pivots)
{
    for (int k = 0; k < n; k++) {
        int p = k;
        double best = fabs(A[k * n + k]);
        for (int i = k + 1; i < n; i++) {
            double v = fabs(A[i * n + k]);
            if (v > best) {
                best = v;
                p = i;
            }
        }
        pivots[k] = p;
        /* An exactly zero (or non-finite) pivot leaves no usable factorization. */
        if (best == 0.0 || !isfinite(best)) {
            return 1;
        }
        if (p != k) {
            for (int j = 0; j < n; j++) {
                double tmp = A[k * n + j];
                A[k * n + j] = A[p * n + j];
                A[p * n + j] = tmp;
            }
        }
        double inv = 1.0 / A[k * n + k];
        for (int i = k + 1; i < n; i++) {
            double m = A[i * n + k] * inv;
            A[i * n + k] = m;
            if (m != 0.0) {
                for (int j = k + 1; j < n; j++) {
                    A[i * n + j] -= m * A[k * n + j];
                }
            }
        }
    }
    return 0;
}

void lu_solve(int n, const double *LU, const int *pivots, double *b)
{
    /* Apply the row swaps in the order they were made, then L y = Pb, then U x = y. */
    for (int k = 0; k < n; k++) {
        int p = pivots[k];
        if (p != k) {
            double tmp = b[k];
            b[k] = b[p];
            b[p] = tmp;
        }
    }
    for (int i = 1; i < n; i++) {
        double s = b[i];
        for (int j = 0; j < i; j++) {
            s -= LU[i * n + j] * b[j];
        }
        b[i] = s;
    }
    for (int i = n - 1; i >= 0; i--) {
        double s = b[i];
        for (int j = i + 1; j < n; j++) {
            s -= LU[i * n + j] * b[j];
        }
        b[i] = s / LU[i * n + i];
    }
}
