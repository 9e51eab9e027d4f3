/* The physical limit of a co-simulation: the same FMUs, the same FMI calls in the same schedule,
 * and no master around them. benchmarks/native.py writes the schedule into a plain text file:
 *
 *   macro <n_macro> <H> <components>
 *   component <library.so> <guid> <resource URI> <name> <k> <h> <feedthrough> <params> <inputs> <outputs>
 *     <params lines:  R|I|B <vr> <value>>
 *     <inputs lines:  <vr> <source component> <source output index>   (source -1: constant <value>)>
 *     <outputs lines: <vr> <read after step m of k: k flags 0/1>>
 *   resample <count> <component index ...>
 *
 * Per macro step, every component in order: k times set all inputs (one fmi2SetReal), fmi2DoStep,
 * set them again where outputs depend on inputs (feedthrough 1: the master hands over the inputs
 * at the step's end), read the outputs (one fmi2GetReal) where the schedule reads them. Inputs hold the source's
 * sample at the macro step's start (the master's order-0 Jacobi coupling; higher orders add a few
 * multiply-adds per input). The outputs at each macro step's end are copied into a results array,
 * as a recorder would. Prints the wall time of the stepping loop in seconds.
 *
 * With --equal-work it also makes the calls the master's semantics needs at each macro step's end
 * (its resampling, kernel.h): each component of the `resample` line, in that order, sets its inputs
 * to its sources' samples at the macro step's end and reads its outputs again, so that no output
 * that depends on inputs lags its time. Without it, it is the bare loop of a master that lets them lag.
 *
 * Build: cc -O2 -std=c99 -o harness harness.c -ldl
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef void *(*instantiate_fn)(const char *, int, const char *, const char *, const void *, int, int);
typedef int (*setup_fn)(void *, int, double, double, int, double);
typedef int (*plain_fn)(void *);
typedef int (*set_real_fn)(void *, const unsigned *, size_t, const double *);
typedef int (*get_real_fn)(void *, const unsigned *, size_t, double *);
typedef int (*set_int_fn)(void *, const unsigned *, size_t, const int *);
typedef int (*do_step_fn)(void *, double, double, int);

typedef struct {
    void (*logger)(void *, const char *, int, const char *, const char *, ...);
    void *(*allocate)(size_t, size_t);
    void (*free)(void *);
    void *step_finished;
    void *env;
} callbacks;

typedef struct {
    void *c;
    set_real_fn set_real;
    get_real_fn get_real;
    do_step_fn do_step;
    int k, feedthrough;
    double h;
    int n_in, n_out;
    unsigned *in_vr, *out_vr;
    int *src, *src_out;
    double *in, *out;
    unsigned char *reads; /* [k] */
} component;

static void logger(void *env, const char *name, int status, const char *category, const char *message, ...) {
    (void)env;
    if (status > 1) fprintf(stderr, "%s [%s]: %s\n", name, category, message);
}

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "missing %s\n", name);
        exit(2);
    }
    return f;
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char **argv) {
    const int equal_work = argc == 3 && strcmp(argv[2], "--equal-work") == 0;
    if (argc != 2 && !equal_work) {
        fprintf(stderr, "usage: harness SCHEDULE [--equal-work]\n");
        return 2;
    }
    FILE *f = fopen(argv[1], "r");
    if (!f) return 2;
    long n_macro;
    double H;
    int nc;
    if (fscanf(f, " macro %ld %lf %d", &n_macro, &H, &nc) != 3) return 2;
    component *comps = calloc((size_t)nc, sizeof *comps);
    static callbacks cb = {logger, calloc, free, NULL, NULL};
    for (int i = 0; i < nc; i++) {
        component *c = &comps[i];
        char lib_path[4096], guid[256], uri[4096], name[256];
        int n_par;
        if (fscanf(f, " component %4095s %255s %4095s %255s %d %lf %d %d %d %d", lib_path, guid, uri, name, &c->k,
                   &c->h, &c->feedthrough, &n_par, &c->n_in, &c->n_out) != 10)
            return 2;
        void *lib = dlopen(lib_path, RTLD_NOW | RTLD_LOCAL);
        if (!lib) {
            fprintf(stderr, "%s\n", dlerror());
            return 2;
        }
        c->c = ((instantiate_fn)sym(lib, "fmi2Instantiate"))(name, 1, guid, uri, &cb, 0, 0);
        if (!c->c) return 3;
        c->set_real = (set_real_fn)sym(lib, "fmi2SetReal");
        c->get_real = (get_real_fn)sym(lib, "fmi2GetReal");
        c->do_step = (do_step_fn)sym(lib, "fmi2DoStep");
        set_int_fn set_int = (set_int_fn)sym(lib, "fmi2SetInteger");
        set_int_fn set_bool = (set_int_fn)sym(lib, "fmi2SetBoolean");
        for (int p = 0; p < n_par; p++) {
            char t;
            unsigned vr;
            double v;
            if (fscanf(f, " %c %u %lf", &t, &vr, &v) != 3) return 2;
            int iv = (int)v, st = t == 'R' ? c->set_real(c->c, &vr, 1, &v) : (t == 'I' ? set_int : set_bool)(c->c, &vr, 1, &iv);
            if (st > 1) return 3;
        }
        c->in_vr = calloc((size_t)c->n_in + 1, sizeof(unsigned));
        c->src = calloc((size_t)c->n_in + 1, sizeof(int));
        c->src_out = calloc((size_t)c->n_in + 1, sizeof(int));
        c->in = calloc((size_t)c->n_in + 1, sizeof(double));
        for (int j = 0; j < c->n_in; j++) {
            if (fscanf(f, " %u %d", &c->in_vr[j], &c->src[j]) != 2) return 2;
            if (c->src[j] < 0 ? fscanf(f, " %lf", &c->in[j]) != 1 : fscanf(f, " %d", &c->src_out[j]) != 1) return 2;
        }
        c->out_vr = calloc((size_t)c->n_out + 1, sizeof(unsigned));
        c->out = calloc((size_t)c->n_out + 1, sizeof(double));
        c->reads = calloc((size_t)c->k, 1);
        for (int j = 0; j < c->n_out; j++)
            if (fscanf(f, " %u", &c->out_vr[j]) != 1) return 2;
        for (int m = 0; m < c->k; m++) {
            int r;
            if (fscanf(f, " %d", &r) != 1) return 2;
            c->reads[m] = (unsigned char)r;
        }
        if (((setup_fn)sym(lib, "fmi2SetupExperiment"))(c->c, 0, 0.0, 0.0, 1, (double)n_macro * H) > 1) return 3;
        if (((plain_fn)sym(lib, "fmi2EnterInitializationMode"))(c->c) > 1) return 3;
        if (((plain_fn)sym(lib, "fmi2ExitInitializationMode"))(c->c) > 1) return 3;
        if (c->n_out && c->get_real(c->c, c->out_vr, (size_t)c->n_out, c->out) > 1) return 3;
    }
    int n_resample = 0;
    if (fscanf(f, " resample %d", &n_resample) != 1) return 2;
    int *resample = calloc((size_t)n_resample + 1, sizeof(int));
    for (int r = 0; r < n_resample; r++)
        if (fscanf(f, " %d", &resample[r]) != 1) return 2;
    if (!equal_work) n_resample = 0;
    fclose(f);
    int n_rec = 0;
    for (int i = 0; i < nc; i++) n_rec += comps[i].n_out;
    double *rows = malloc(sizeof(double) * (size_t)(n_rec + 1) * 4096);
    long row = 0;

    double t0 = now();
    for (long n = 0; n < n_macro; n++) {
        for (int i = 0; i < nc; i++) { /* Jacobi: every input from the samples at the macro step's start */
            component *c = &comps[i];
            for (int j = 0; j < c->n_in; j++)
                if (c->src[j] >= 0) c->in[j] = comps[c->src[j]].out[c->src_out[j]];
        }
        for (int i = 0; i < nc; i++) {
            component *c = &comps[i];
            for (int m = 0; m < c->k; m++) {
                double t = (double)(n * c->k + m) * c->h;
                if (c->n_in && c->set_real(c->c, c->in_vr, (size_t)c->n_in, c->in) > 1) return 4;
                if (c->do_step(c->c, t, c->h, 1) > 1) return 4;
                if (c->feedthrough && c->set_real(c->c, c->in_vr, (size_t)c->n_in, c->in) > 1) return 4;
                if (c->n_out && c->reads[m] && c->get_real(c->c, c->out_vr, (size_t)c->n_out, c->out) > 1) return 4;
            }
        }
        for (int q = 0; q < n_resample; q++) { /* the step-end inputs final, the outputs read again */
            component *c = &comps[resample[q]];
            for (int j = 0; j < c->n_in; j++)
                if (c->src[j] >= 0) c->in[j] = comps[c->src[j]].out[c->src_out[j]];
            if (c->set_real(c->c, c->in_vr, (size_t)c->n_in, c->in) > 1) return 4;
            if (c->get_real(c->c, c->out_vr, (size_t)c->n_out, c->out) > 1) return 4;
        }
        double *r = rows + (size_t)(row++ % 4096) * (size_t)(n_rec + 1);
        r[0] = (double)(n + 1) * H;
        for (int i = 0, o = 1; i < nc; o += comps[i].n_out, i++)
            memcpy(r + o, comps[i].out, sizeof(double) * (size_t)comps[i].n_out);
    }
    printf("%.9f\n", now() - t0);
    return 0;
}
