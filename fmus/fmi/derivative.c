/* derivative.c: GetDirectionalDerivative (FMI 2.0 and 3.0, scalar Real variables).
 *
 * d(unknowns)/d(knowns) * seed.  Derivatives with respect to states use the
 * model's analytic Jacobian when it has one; anything else (outputs, inputs,
 * models without a Jacobian) uses central finite differences of the model
 * functions along the seed direction.  The real slots are restored afterwards,
 * so the call leaves the instance unchanged.
 */
#include <float.h>
#include <math.h>
#include <string.h>

#include "instance.h"

static int state_index(const Instance *inst, const Variable *v) {
    for (int i = 0; i < inst->model->n_states; i++)
        if (inst->model->state_slots[i] == v->slot) return i;
    return -1;
}

static int derivative_index(const Instance *inst, const Variable *v) {
    for (int i = 0; i < inst->model->n_states; i++)
        if (inst->model->derivative_slots[i] == v->slot) return i;
    return -1;
}

/* Evaluate all unknowns with the knowns at base + eps * seed; write them into out. */
static int evaluate(Instance *inst, const unsigned unknown[], size_t n_unknown, const unsigned known[],
                    size_t n_known, const double seed[], double eps, double out[]) {
    const ModelDef *m = inst->model;
    int rc;
    for (size_t j = 0; j < n_known; j++)
        inst->reals[m->variables[known[j]].slot] = inst->fd_seed_base[j] + eps * seed[j];
    /* Derivatives, then outputs: a model may write slots the other reads (manipulator
     * warm-starts its loop closure from them), so the order is part of the result. */
    rc = eval_derivatives(inst);
    rc |= eval_outputs(inst);
    for (size_t i = 0; i < n_unknown; i++) out[i] = inst->reals[m->variables[unknown[i]].slot];
    return rc;
}

LayerStatus directional_derivative(Instance *inst, const char *fn, const unsigned unknown[], size_t n_unknown,
                                   const unsigned known[], size_t n_known, const double seed[], double result[]) {
    const ModelDef *m = inst->model;
    int analytic = m->jacobian != NULL;
    double scale = 0.0, seed_norm = 0.0, eps;
    int rc;

    if (n_known > (size_t)m->n_variables || n_unknown > (size_t)m->n_variables) {
        layer_log(inst, LOG_ERROR, "%s: %zu unknowns and %zu knowns but the model has only %d variables", fn,
                  n_unknown, n_known, m->n_variables);
        return LAYER_ERROR;
    }
    for (size_t i = 0; i < n_unknown + n_known; i++) {
        unsigned vr = i < n_unknown ? unknown[i] : known[i - n_unknown];
        const Variable *v = variable_of(inst, vr);
        if (!v || v->type != T_REAL || v->causality == C_INDEPENDENT || variable_size(inst, vr) != 1) {
            const char *why = !v                  ? "out of range"
                              : v->type != T_REAL ? "not a Real variable"
                                                  : "an array or time, not a scalar Real variable";
            layer_log(inst, LOG_ERROR, "%s: value reference %u is %s", fn, vr, why);
            return LAYER_ERROR;
        }
        if (i < n_unknown ? derivative_index(inst, v) < 0 : state_index(inst, v) < 0) analytic = 0;
    }
    if (refresh(inst, 1, fn)) return LAYER_ERROR;

    if (analytic) { /* J * seed with the model's Jacobian at the current point */
        int n = m->n_states;
        gather_states(inst, inst->x);
        if (m->jacobian(inst, inst->core->time, inst->x, inst->jac) != MODEL_OK) {
            layer_log(inst, LOG_ERROR, "%s: model Jacobian failed at t = %.17g%s", fn, inst->core->time,
                      model_error_suffix(inst));
            return LAYER_ERROR;
        }
        for (size_t i = 0; i < n_unknown; i++) {
            int row = derivative_index(inst, &m->variables[unknown[i]]);
            double sum = 0.0;
            for (size_t j = 0; j < n_known; j++)
                sum += inst->jac[row * n + state_index(inst, &m->variables[known[j]])] * seed[j];
            result[i] = sum;
        }
        return LAYER_OK;
    }

    /* Central differences along the seed, step relative to the size of the knowns. */
    memcpy(inst->saved_reals, inst->reals, sizeof(double) * (size_t)m->n_reals);
    for (size_t j = 0; j < n_known; j++) {
        inst->fd_seed_base[j] = inst->reals[m->variables[known[j]].slot];
        scale = fmax(scale, fabs(inst->fd_seed_base[j]));
        seed_norm = fmax(seed_norm, fabs(seed[j]));
    }
    if (seed_norm == 0.0) {
        for (size_t i = 0; i < n_unknown; i++) result[i] = 0.0;
        return LAYER_OK;
    }
    eps = cbrt(DBL_EPSILON) * fmax(1.0, scale) / seed_norm;
    rc = evaluate(inst, unknown, n_unknown, known, n_known, seed, eps, inst->fd_plus);
    rc |= evaluate(inst, unknown, n_unknown, known, n_known, seed, -eps, inst->fd_minus);
    memcpy(inst->reals, inst->saved_reals, sizeof(double) * (size_t)m->n_reals);
    if (rc) {
        layer_log(inst, LOG_ERROR, "%s: model equations failed while differentiating at t = %.17g%s", fn,
                  inst->core->time, model_error_suffix(inst));
        return LAYER_ERROR;
    }
    for (size_t i = 0; i < n_unknown; i++) result[i] = (inst->fd_plus[i] - inst->fd_minus[i]) / (2.0 * eps);
    return LAYER_OK;
}
