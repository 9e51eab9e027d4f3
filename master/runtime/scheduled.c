/* Scheduled Execution components (kernel.h: mk_scheduled; master/clocks.py): the master activates
 * the model partitions of their input clocks at the points of their grid. Included by kernel.c,
 * whose helpers (set_inputs, read_outputs, fail ...) it uses. */

typedef int fmi3_activate_model_partition(void *, uint32_t, double);
typedef int fmi3_get_clock(void *, const uint32_t *, size_t, bool *);
typedef int fmi3_get_interval_decimal(void *, const uint32_t *, size_t, double *, int32_t *);

#define FMI3_INTERVAL_CHANGED 2 /* fmi3IntervalQualifier fmi3IntervalChanged */

/* After an event iteration (or a point's activations): component ci's output clocks read with
 * fmi3GetClock and their ticks counted. */
static int32_t count_clocks(mk_kernel *k, int32_t ci, int64_t j) {
    mk_component *c = &k->components[ci];
    for (int32_t i = 0; i < c->n_out_clocks; i++) {
        bool ticked = false;
        int st = ((fmi3_get_clock *)c->get_clock)(c->instance, &c->out_clock_vrs[i], 1, &ticked);
        if (st > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, MK_CALL_GET_CLOCK, st, j);
        c->out_clock_ticks[i] += ticked;
    }
    return MK_DONE;
}

/* Whether input clock i ticks at point j. */
static bool se_due(const mk_scheduled *s, int32_t i, int64_t j) {
    if (s->tick[i] == MK_TICK_PERIODIC) return j >= s->phase[i] && (j - s->phase[i]) % s->every[i] == 0;
    if (s->tick[i] == MK_TICK_COUNTDOWN || s->tick[i] == MK_TICK_LINKED) return s->due[i] == j;
    int64_t lo = s->first[i], hi = s->first[i + 1]; /* a triggered clock: its points, ascending */
    while (lo < hi) {
        const int64_t mid = lo + (hi - lo) / 2;
        if (s->points[mid] < j) lo = mid + 1;
        else hi = mid;
    }
    return lo < s->first[i + 1] && s->points[lo] == j;
}

/* After an activation at point j: the countdown clocks whose interval the FMU has just set tick that
 * interval later, a whole number of communication steps (an interval of 0: at j, after it). */
static int32_t se_countdowns(mk_kernel *k, int32_t ci, int64_t j) {
    mk_component *c = &k->components[ci];
    mk_scheduled *s = c->scheduled;
    for (int32_t i = 0; i < s->n_clocks; i++) {
        if (s->tick[i] != MK_TICK_COUNTDOWN) continue;
        double interval = 0.0;
        int32_t qualifier = 0;
        int st = ((fmi3_get_interval_decimal *)s->get_interval)(c->instance, &s->vrs[i], 1, &interval, &qualifier);
        if (st > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, MK_CALL_GET_INTERVAL, st, j);
        if (qualifier != FMI3_INTERVAL_CHANGED) continue;
        const double steps = interval / c->h;
        const double whole = nearbyint(steps);
        if (!(interval >= 0.0) || fabs(steps - whole) > 1e-9 * fmax(1.0, whole)) {
            k->error.variable = i;
            k->error.value = interval;
            return fail(k, MK_CLOCK, ci, MK_CALL_GET_INTERVAL, 0, j);
        }
        s->due[i] = j + (int64_t)whole;
    }
    return MK_DONE;
}

/* The activations of component ci at point j: every input clock due there, the highest-priority
 * one first after every activation (a countdown clock set due at j by one of them too), each once
 * (at most MK_MAX_CLOCKS input clocks); then its output clocks read and their ticks counted. */
static int32_t se_activate(mk_kernel *k, int32_t ci, int64_t j) {
    mk_component *c = &k->components[ci];
    mk_scheduled *s = c->scheduled;
    const double t = point_time(c, j);
    uint64_t done = 0; /* bit i: clock i activated at j (repeated steps activate again from a restored state) */
    for (int32_t i = 0; i < s->n_clocks;) {
        if ((done >> i & 1) || !se_due(s, i, j)) {
            i++;
            continue;
        }
        done |= (uint64_t)1 << i;
        int st = ((fmi3_activate_model_partition *)s->activate_model_partition)(c->instance, s->vrs[i], t);
        if (st > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, MK_CALL_ACTIVATE_MODEL_PARTITION, st, j);
        s->activations[i]++;
        int32_t code = se_countdowns(k, ci, j);
        if (code != MK_DONE) return code;
        i = 0;
    }
    return count_clocks(k, ci, j);
}

/* Communication step m of a Scheduled Execution component, from point j to j + 1 (kernel.h:
 * mk_scheduled): its inputs at t_{j+1} (the step-end block), the activations at j + 1, its outputs
 * read into sample j + 1. */
static int32_t se_step(mk_kernel *k, int32_t ci, const double *u, int32_t m, int64_t j) {
    mk_component *c = &k->components[ci];
    const int64_t t0 = now_ns();
    int32_t call = 0, code;
    int st;
    const double *now = u + (c->n_values > 1 ? c->n_in : 0);
    if (c->n_in && (st = set_inputs(c, now, &call)) > STATUS_OK) return fail(k, MK_FMI_ERROR, ci, call, st, j);
    const int32_t n_text_in = c->n_in_string + c->n_in_binary;
    if (n_text_in && (st = set_texts(c, c->in_string_vrs, c->string_u + (size_t)m * n_text_in * MK_STRING_SLOT,
                                     c->n_in_string, c->n_in_binary, &call)) > STATUS_OK)
        return fail(k, MK_FMI_ERROR, ci, call, st, j);
    mk_scheduled *s = c->scheduled;
    for (int32_t i = 0; i < s->n_clocks; i++) /* a linked clock ticks where its source's count grew */
        if (s->tick[i] == MK_TICK_LINKED && now[s->slot[i]] != s->seen[i]) s->due[i] = j + 1, s->seen[i] = now[s->slot[i]];
    if ((code = se_activate(k, ci, j + 1)) != MK_DONE) return code;
    double *row = c->hist + ((j + 1) % c->cap) * c->n_out;
    if (c->n_out && c->reads[m] && (code = read_outputs(k, ci, row, j, j + 1)) != MK_DONE) return code;
    if (c->n_out_string + c->n_out_binary && c->reads[m] && (code = read_strings(k, ci, c->strings, j, j + 1)) != MK_DONE)
        return code;
    *c->fmu_time += 1e-9 * (double)(now_ns() - t0);
    (*c->steps)++;
    if (c->n_out && c->reads[m] && check_sample(k, ci, row, j + 1)) return k->error.code;
    return MK_DONE;
}

int32_t mk_scheduled_start(mk_kernel *k, int32_t ci) {
    mk_component *c = &k->components[ci];
    const int64_t t0 = now_ns();
    int32_t code = se_activate(k, ci, 0);
    if (code == MK_DONE && c->n_out) code = read_outputs(k, ci, c->hist, 0, 0);
    if (code == MK_DONE && c->n_out_string + c->n_out_binary) code = read_strings(k, ci, c->strings, 0, 0);
    *c->fmu_time += 1e-9 * (double)(now_ns() - t0);
    return code;
}
