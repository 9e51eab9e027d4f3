/* step.c: DoStep (FMI 2.0 and 3.0) with fixed internal steps and interpolated inputs.
 *
 * Input rule (canInterpolateInputs): fmi2SetRealInputDerivatives(vr, k, d_k)
 * gives the k-th time derivative (k = 1..3) of a Real input at the current
 * communication point t_c.  Inside the next fmi2DoStep, before every model
 * evaluation at a substep or stage time s, each Real input slot is set to
 *     u(s) = u0 + sum_k d_k (s - t_c)^k / k!
 * where u0 is the value the master set.  After the step the input slots get
 * back exactly u0 and all derivatives are cleared: the master sets new ones
 * for every step (no derivatives given = inputs held constant).  FMI 3.0 has no input
 * derivatives: where the importer passed an intermediateUpdate callback, the FMU asks it for
 * its intermediate-update inputs at every new stage time s instead (intermediateVariableSetRequested,
 * the importer sets them with fmi3SetFloat64 inside the callback; fmi3.c); without one its inputs are
 * held constant over a step.  Either way the inputs get back the values the importer set before
 * the step when it ends.
 */
#include <math.h>
#include <string.h>

#include "instance.h"

/* Evaluate the input polynomials at time t into the input slots. */
static void apply_input_polynomials(Instance *inst, double t) {
    double dt = t - inst->comm_point;
    for (int i = 0; i < inst->n_real_inputs; i++) {
        const double *d = inst->input_derivs + (size_t)i * MAX_INPUT_ORDER;
        /* Horner form of u0 + d1 dt + d2 dt^2/2 + d3 dt^3/6 */
        double u = inst->input_values[i] + dt * (d[0] + dt * (d[1] / 2.0 + dt * d[2] / 6.0));
        inst->reals[inst->real_input_slot[i]] = u;
    }
}

/* The inputs of time t in the input slots: the importer's (FMI 3.0 intermediate update, asked once per
 * new time: the stages of a method at one time share them), else the FMI 2.0 input polynomials. */
static void inputs_at(Instance *inst, double t) {
    if (inst->ask_inputs) {
        if (t != inst->asked_time) inst->ask_inputs(inst, t);
        inst->asked_time = t;
    } else if (inst->core->have_input_derivatives)
        apply_input_polynomials(inst, t);
}

int rhs_with_inputs(void *ctx, double t, const double *x, double *dx) {
    Instance *inst = ctx;
    inputs_at(inst, t);
    if (!inst->model->derivatives) return 0; /* no states: nothing to integrate */
    if (kept_rhs(inst, t, x, dx)) return 0;  /* evaluated already: the master read outputs there */
    ModelStatus st = inst->model->derivatives(inst, t, x, dx);
    if (st == MODEL_FATAL) inst->core->fatal = 1;
    if (st == MODEL_TERMINATE) { /* the step completes; the simulation ends after it */
        inst->core->terminate = 1;
        return 0;
    }
    return st != MODEL_OK;
}

int jac_with_inputs(void *ctx, double t, const double *x, double *J) {
    Instance *inst = ctx;
    inputs_at(inst, t);
    return inst->model->jacobian(inst, t, x, J) != MODEL_OK;
}

int indicators_with_inputs(void *ctx, double t, const double *x, double *z) {
    Instance *inst = ctx;
    inputs_at(inst, t);
    ModelStatus st = inst->model->event_indicators(inst, t, x, z);
    if (st == MODEL_FATAL) inst->core->fatal = 1;
    return st != MODEL_OK;
}

int completed_in_step(void *ctx, double t, const double *x, int *event, int *stop) {
    Instance *inst = ctx;
    inputs_at(inst, t);
    *event = inst->model->step_event(inst, t, x) != 0;
    *stop = 0;
    return 0;
}

/* The event iteration at (t, x) inside doStep: the instance at that time and state, the inputs of
 * time t; afterwards x as the model left it. */
int event_in_step(void *ctx, double t, double *x, double *next_time, int *stop) {
    Instance *inst = ctx;
    int changed = 0;
    if (inst->event_mode_used && (inst->early_return_allowed || t >= inst->comm_end)) {
        *stop = ODE_EVENT; /* FMI 3.0 event mode: the importer handles it (fmi3UpdateDiscreteStates) */
        return 0;
    }
    inputs_at(inst, t);
    inst->core->time = t;
    scatter_states(inst, x);
    mark_dirty(inst);
    if (event_iteration(inst, "doStep", &changed, stop)) return 1;
    gather_states(inst, x);
    *next_time = inst->core->next_event_time;
    return 0;
}

/* Number of internal steps in a communication step H, or 0 (logged) if H is not a multiple. */
static long long internal_steps(Instance *inst, const char *function, double H) {
    double h = inst->reals[R_INTERNAL_STEP];
    double ratio, n;
    if (!(h > 0.0)) return 1;
    ratio = H / h;
    n = nearbyint(ratio);
    if (n < 1.0 || fabs(ratio - n) > 1e-9 * ratio) {
        layer_log(inst, LOG_ERROR,
                  "%s: communication step %.17g s is not an integer multiple of internal_step %.17g s "
                  "(ratio %.17g)",
                  function, H, h, ratio);
        return 0;
    }
    return (long long)n;
}

LayerStatus do_step(Instance *inst, const char *function, double t, double H) {
    const ModelDef *m = inst->model;
    Core *c = inst->core;
    SolverKind kind = (SolverKind)inst->integers[I_SOLVER];
    int n = m->n_states, rc = 0;
    long long steps;
    double h;

    if (!isfinite(t) || !isfinite(H) || !(H > 0.0)) {
        layer_log(inst, LOG_ERROR, "%s: invalid step: t = %g s, H = %g s (need finite t and H > 0)", function, t,
                  H);
        return LAYER_ERROR;
    }
    if (fabs(t - c->time) > 1e-9 * fmax(1.0, fabs(t))) {
        layer_log(inst, LOG_ERROR, "%s: communication point %.17g s does not match the FMU time %.17g s", function,
                  t, c->time);
        return LAYER_ERROR;
    }
    /* the rest of a step returned early from (FMI 3.0 event mode): on that step's grid, to its end (t + H
     * but for the rounding of the importer's H = end - t) */
    const int resume =
        c->grid_steps > 0 && t > c->grid_t0 && fabs(t + H - c->grid_t1) <= 1e-9 * (c->grid_t1 - c->grid_t0);
    double t0 = t, t1 = t + H, reached = t1;
    if (resume) {
        steps = c->grid_steps, h = c->grid_h, t0 = c->grid_t0, t1 = c->grid_t1;
    } else {
        steps = internal_steps(inst, function, H);
        if (steps == 0) return LAYER_ERROR;
        h = H / (double)steps;
    }
    c->grid_steps = 0;
    c->event_pending = 0;

    for (int i = 0; i < inst->n_real_inputs; i++)
        inst->input_values[i] = inst->reals[inst->real_input_slot[i]];
    inst->comm_point = t;
    inst->asked_time = NAN;
    inst->comm_end = t1;
    gather_states(inst, inst->x);
    if (n > 0 || m->update) { /* substep j from t + j h (from the integer j: no drift), events on the way */
        const OdeProblem problem = {kind,
                                    inst->memory,
                                    inst->work,
                                    n,
                                    m->n_event_indicators,
                                    rhs_with_inputs,
                                    m->jacobian ? jac_with_inputs : NULL,
                                    m->event_indicators ? indicators_with_inputs : NULL,
                                    m->step_event ? completed_in_step : NULL,
                                    event_in_step,
                                    inst,
                                    EVENT_TOLERANCE};
        rc = ode_advance_from(&problem, inst->events, t0, h, steps, t1, t, inst->x, &c->next_event_time,
                              &c->events, &reached);
        if (rc == ODE_STOP) { /* the model ends the simulation: this step completes */
            c->terminate = 1;
            rc = 0;
        } else if (rc == ODE_EVENT) { /* event mode: the step ends at the event; the importer handles it */
            c->event_pending = 1;
            if (reached < t1) c->grid_steps = steps, c->grid_h = h, c->grid_t0 = t0, c->grid_t1 = t1;
            rc = 0;
        }
    }

    /* Restore the inputs the master set and forget this step's derivatives. */
    for (int i = 0; i < inst->n_real_inputs; i++)
        inst->reals[inst->real_input_slot[i]] = inst->input_values[i];
    memset(inst->input_derivs, 0, sizeof(double) * (size_t)inst->n_real_inputs * MAX_INPUT_ORDER);
    c->have_input_derivatives = 0;

    if (rc != 0) {
        layer_log(inst, LOG_ERROR, "%s: %s in the step from t = %.17g s (h = %g s)%s", function,
                  rc == 2 ? "singular linear system" : "model equations failed", t, h, model_error_suffix(inst));
        c->state = ST_ERROR;
        return c->fatal ? LAYER_FATAL : LAYER_ERROR;
    }
    scatter_states(inst, inst->x);
    c->time = reached; /* t1, or the event's time where the step ended there */
    mark_dirty(inst);
    if (refresh(inst, 0, function) || check_finite(inst, function)) {
        c->state = ST_ERROR;
        return LAYER_ERROR;
    }
    if (c->terminate) {
        layer_log(inst, LOG_INFO, "%s: the model ends the simulation at t = %.17g s", function, c->time);
        return LAYER_DISCARD; /* FMI 2.0: fmi2GetBooleanStatus(fmi2Terminated) says why; FMI 3.0 reports
                                 fmi3OK with terminateSimulation */
    }
    return LAYER_OK;
}
