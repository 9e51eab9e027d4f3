/* describe.c: print a model's ModelDef and the layer's constants as JSON on stdout.
 *
 * Linked with the model's sources and the layer, never into the FMU.
 * master/fmubuild.py turns the JSON into modelDescription.xml, so the C side is
 * the only source of truth: the variable table (with the extents of FMI 3.0
 * arrays), each variable's effective `initial` (the layer's rule), the log
 * categories, the highest input derivative order and the number of solvers.
 */
#include <math.h>
#include <stdio.h>

#include "instance.h"

static void json_string(const char *s) {
    if (!s) {
        fputs("null", stdout);
        return;
    }
    putchar('"');
    for (; *s; s++) {
        unsigned char ch = (unsigned char)*s;
        if (ch == '"' || ch == '\\')
            printf("\\%c", ch);
        else if (ch < 0x20)
            printf("\\u%04x", ch);
        else
            putchar(ch);
    }
    putchar('"');
}

/* Non-finite numbers are not JSON: write them as the strings "inf", "-inf", "nan". */
static void json_number(double x) {
    if (isfinite(x))
        printf("%.17g", x);
    else
        fputs(x > 0 ? "\"inf\"" : (x < 0 ? "\"-inf\"" : "\"nan\""), stdout);
}

static void json_ints(const int *a, int n) {
    putchar('[');
    for (int i = 0; i < n; i++) printf("%s%d", i ? ", " : "", a[i]);
    putchar(']');
}

int main(void) {
    static const char *const types[T_COUNT] = {"Real",  "Integer", "Boolean", "String", "Solver",
                                               "Float32", "Int8",  "UInt8",   "Int16",  "UInt16",
                                               "UInt32",  "Int64", "UInt64",  "Binary", "Clock"};
    static const char *const causalities[] = {"parameter", "calculatedParameter", "input",
                                              "output",    "local",               "independent"};
    static const char *const variabilities[] = {"constant", "fixed", "tunable", "discrete", "continuous"};
    static const char *const initials[] = {NULL, "exact", "approx", "calculated"};
    const ModelDef *m = &MODEL;

    printf("{\n\"identifier\": ");
    json_string(m->identifier);
    printf(",\n\"guid\": ");
    json_string(m->guid);
    printf(",\n\"description\": ");
    json_string(m->description);
    printf(",\n\"n_reals\": %d, \"n_integers\": %d, \"n_booleans\": %d, \"n_strings\": %d,\n", m->n_reals,
           m->n_integers, m->n_booleans, m->n_strings);
    printf("\"n_int64s\": %d, \"n_uint64s\": %d, \"n_binaries\": %d, \"fmi3_only\": %s,\n", m->n_int64s,
           m->n_uint64s, m->n_binaries, m->fmi3_only ? "true" : "false");
    printf("\"me_only\": %s,\n", m->me_only ? "true" : "false");
    printf("\"string_capacity\": %d, \"binary_capacity\": %d,\n", STRING_CAPACITY, BINARY_CAPACITY);
    printf("\"n_states\": %d,\n\"state_slots\": ", m->n_states);
    json_ints(m->state_slots, m->n_states);
    printf(",\n\"derivative_slots\": ");
    json_ints(m->derivative_slots, m->n_states);
    printf(",\n\"max_input_derivative_order\": %d, \"solver_count\": %d,\n\"log_categories\": [", MAX_INPUT_ORDER,
           SOLVER_COUNT);
    for (int k = 0; k < LOG_N_CATEGORIES; k++) {
        printf("%s{\"name\": ", k ? ", " : "");
        json_string(LOG_CATEGORY_NAMES[k]);
        printf(", \"description\": ");
        json_string(LOG_CATEGORY_DESCRIPTIONS[k]);
        putchar('}');
    }
    printf("],\n\"has_initialize\": %s, \"has_jacobian\": %s, \"has_outputs\": %s,\n",
           m->initialize ? "true" : "false", m->jacobian ? "true" : "false", m->outputs ? "true" : "false");
    printf("\"n_event_indicators\": %d, \"event_indicator_vrs\": ", m->n_event_indicators);
    json_ints(m->event_indicator_vrs, m->event_indicator_vrs ? m->n_event_indicators : 0);
    printf(", \"has_step_event\": %s,\n", m->step_event ? "true" : "false");
    static const char *const clock_variabilities[] = {"constant", "fixed",     "tunable",
                                                      "changing", "countdown", "triggered"};
    printf("\"has_activate\": %s, \"clocks\": [", m->activate ? "true" : "false");
    for (int k = 0; k < m->n_clocks; k++) {
        const ClockDef *c = &m->clocks[k];
        printf("%s{\"vr\": %d, \"interval_variability\": \"%s\", \"interval\": ", k ? ", " : "", c->vr,
               clock_variabilities[c->variability]);
        json_number(c->interval);
        printf(", \"priority\": %d, \"interval_slot\": %d}", c->priority, c->interval_slot);
    }
    printf("],\n");
    printf("\"default_step_size\": ");
    json_number(m->default_step_size);
    printf(",\n\"variables\": [\n");
    for (int i = 0; i < m->n_variables; i++) {
        const Variable *v = &m->variables[i];
        printf("  {\"name\": ");
        json_string(v->name);
        printf(", \"type\": \"%s\", \"causality\": \"%s\", \"variability\": \"%s\", \"initial\": ",
               types[v->type], causalities[v->causality], variabilities[v->variability]);
        json_string(initials[v->initial]);
        printf(", \"effective_initial\": ");
        json_string(initials[effective_initial(v)]);
        printf(", \"slot\": %d, \"start\": ", v->slot);
        json_number(v->start);
        printf(", \"start_string\": ");
        json_string(v->start_string);
        printf(", \"min\": ");
        json_number(v->min);
        printf(", \"max\": ");
        json_number(v->max);
        printf(", \"unit\": ");
        json_string(v->unit);
        printf(", \"description\": ");
        json_string(v->description);
        printf(", \"derivative_of\": %d, \"dependencies\": ", v->derivative_of);
        json_string(v->dependencies);
        printf(", \"clocks\": ");
        json_string(m->clocked ? m->clocked[i] : NULL);
        printf(", \"dimensions\": ");
        {
            int n = 0;
            while (m->dimensions && n < MAX_DIMENSIONS && m->dimensions[i][n] > 0) n++;
            json_ints(m->dimensions ? m->dimensions[i] : NULL, n);
        }
        printf("}%s\n", i + 1 < m->n_variables ? "," : "");
    }
    printf("]\n}\n");
    return 0;
}
