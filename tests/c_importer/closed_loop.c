/* A two-FMU co-simulation master in C: loads two FMU binaries, resolves the
 * functions it calls through the official typedefs of fmi2FunctionTypes.h,
 * sets start values, and steps both with a fixed communication step and
 * Jacobi ordering (at t_k each FMU receives the other's outputs at t_k, then
 * both step to t_k+1), as demo/cosim.py does with fmpy. Built for Linux and,
 * with x86_64-w64-mingw32-gcc, for Windows (run under wine) by
 * tests/test_windows_binaries.py, which compares the two runs.
 *
 * usage: closed_loop <wiring file>
 * The wiring file, one directive a line, FMUs numbered 0 and 1:
 *   library <fmu> <path of the binary>   (the rest of the line)
 *   guid <fmu> <guid>
 *   real <fmu> <value reference> <value>      set after instantiation
 *   boolean <fmu> <value reference> <0|1>     set after instantiation
 *   connect <from fmu> <output vr> <to fmu> <input vr>
 *   run <steps> <step size>
 * Prints one line per communication point t_k (k = 0..steps): t_k, then the
 * output of every connection in the file's order, %.17g. Exits non-zero on
 * any status other than fmi2OK, a missing symbol or a malformed file. */

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2FunctionTypes.h"
#include "fmu_library.h"

#define FMUS 2
#define MAX_ITEMS 64
#define MAX_LINE 4096

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    va_list args;
    (void)env;
    fprintf(stderr, "[%s|%s|%d] ", instance ? instance : "?", category ? category : "?",
            (int)status);
    va_start(args, message);
    vfprintf(stderr, message, args);
    va_end(args);
    fputc('\n', stderr);
}

/* The functions this master calls, typed by the standard's typedefs. */
struct fmu {
    char path[MAX_LINE];
    char guid[MAX_LINE];
    fmu_library library;
    fmi2Component component;
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *free_instance;
    fmi2SetupExperimentTYPE *setup_experiment;
    fmi2EnterInitializationModeTYPE *enter_initialization_mode;
    fmi2ExitInitializationModeTYPE *exit_initialization_mode;
    fmi2TerminateTYPE *terminate;
    fmi2GetRealTYPE *get_real;
    fmi2SetRealTYPE *set_real;
    fmi2SetBooleanTYPE *set_boolean;
    fmi2DoStepTYPE *do_step;
};

struct start_value {
    int fmu;
    int is_boolean;
    fmi2ValueReference vr;
    fmi2Real real;
    fmi2Boolean boolean;
};

struct connection {
    int from, to;
    fmi2ValueReference output, input;
};

#define RESOLVE(f, field, name)                                                   \
    do {                                                                          \
        (f)->field = (name##TYPE *)fmu_library_symbol((f)->library, #name);      \
        if ((f)->field == NULL) {                                                 \
            fprintf(stderr, "%s: missing symbol %s\n", (f)->path, #name);         \
            return 2;                                                             \
        }                                                                         \
    } while (0)

#define CHECK(call)                                                     \
    do {                                                                \
        fmi2Status status_ = (call);                                    \
        if (status_ != fmi2OK) {                                        \
            fprintf(stderr, "%s returned %d\n", #call, (int)status_);   \
            return 3;                                                   \
        }                                                               \
    } while (0)

static int load(struct fmu *f) {
    f->library = fmu_library_open(f->path);
    if (f->library == NULL) {
        return 2;
    }
    RESOLVE(f, instantiate, fmi2Instantiate);
    RESOLVE(f, free_instance, fmi2FreeInstance);
    RESOLVE(f, setup_experiment, fmi2SetupExperiment);
    RESOLVE(f, enter_initialization_mode, fmi2EnterInitializationMode);
    RESOLVE(f, exit_initialization_mode, fmi2ExitInitializationMode);
    RESOLVE(f, terminate, fmi2Terminate);
    RESOLVE(f, get_real, fmi2GetReal);
    RESOLVE(f, set_real, fmi2SetReal);
    RESOLVE(f, set_boolean, fmi2SetBoolean);
    RESOLVE(f, do_step, fmi2DoStep);
    return 0;
}

/* The whole wiring, as read from the file. */
struct wiring {
    struct fmu fmus[FMUS];
    struct start_value starts[MAX_ITEMS];
    struct connection connections[MAX_ITEMS];
    int n_starts, n_connections, steps;
    double step_size;
};

static int valid_fmu(int index) {
    return index >= 0 && index < FMUS;
}

/* Reads one directive into `w`; 0 when the line is malformed, names an FMU
 * other than 0 or 1, or overflows a table. */
static int parse_line(const char *line, struct wiring *w) {
    char keyword[32];
    int consumed, rest, a, b, flag;
    unsigned long vr, vr2;
    double value;

    if (sscanf(line, "%31s%n", keyword, &consumed) != 1) {
        return 1; /* blank line */
    }
    line += consumed;
    if (strcmp(keyword, "library") == 0 || strcmp(keyword, "guid") == 0) {
        /* The rest of the line, so that a path may hold spaces. */
        if (sscanf(line, "%d %n", &a, &rest) != 1 || !valid_fmu(a) || line[rest] == '\0') {
            return 0;
        }
        strcpy(strcmp(keyword, "library") == 0 ? w->fmus[a].path : w->fmus[a].guid, line + rest);
        return 1;
    }
    if (strcmp(keyword, "real") == 0 || strcmp(keyword, "boolean") == 0) {
        struct start_value *start = &w->starts[w->n_starts];
        int is_boolean = keyword[0] == 'b';
        if (w->n_starts == MAX_ITEMS ||
            (is_boolean ? sscanf(line, "%d %lu %d", &a, &vr, &flag)
                        : sscanf(line, "%d %lu %lf", &a, &vr, &value)) != 3 ||
            !valid_fmu(a)) {
            return 0;
        }
        start->fmu = a;
        start->is_boolean = is_boolean;
        start->vr = (fmi2ValueReference)vr;
        start->real = is_boolean ? 0.0 : value;
        start->boolean = is_boolean && flag ? fmi2True : fmi2False;
        w->n_starts++;
        return 1;
    }
    if (strcmp(keyword, "connect") == 0) {
        struct connection *c = &w->connections[w->n_connections];
        if (w->n_connections == MAX_ITEMS ||
            sscanf(line, "%d %lu %d %lu", &a, &vr, &b, &vr2) != 4 || !valid_fmu(a) ||
            !valid_fmu(b) || a == b) {
            return 0;
        }
        c->from = a;
        c->output = (fmi2ValueReference)vr;
        c->to = b;
        c->input = (fmi2ValueReference)vr2;
        w->n_connections++;
        return 1;
    }
    if (strcmp(keyword, "run") == 0) {
        return sscanf(line, "%d %lf", &w->steps, &w->step_size) == 2 && w->steps >= 0 &&
               w->step_size > 0.0;
    }
    return 0;
}

int main(int argc, char **argv) {
    static struct wiring w;
    static fmi2Real outputs[MAX_ITEMS];
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    char line[MAX_LINE];
    int line_number = 0, i, k;
    double time;
    FILE *file;

    if (argc != 2) {
        fprintf(stderr, "usage: %s <wiring file>\n", argv[0]);
        return 1;
    }
    file = fopen(argv[1], "r");
    if (file == NULL) {
        perror(argv[1]);
        return 1;
    }
    w.steps = -1;
    while (fgets(line, sizeof line, file) != NULL) {
        line_number++;
        line[strcspn(line, "\r\n")] = '\0';
        if (!parse_line(line, &w)) {
            fprintf(stderr, "%s:%d: not understood (or too many items): %s\n", argv[1],
                    line_number, line);
            fclose(file);
            return 1;
        }
    }
    fclose(file);
    if (w.steps < 0 || w.fmus[0].path[0] == '\0' || w.fmus[1].path[0] == '\0') {
        fprintf(stderr, "%s: needs a library line for FMUs 0 and 1 and a run line\n", argv[1]);
        return 1;
    }

    for (i = 0; i < FMUS; i++) {
        struct fmu *f = &w.fmus[i];
        char name[16];
        int status = load(f);
        if (status != 0) {
            return status;
        }
        sprintf(name, "fmu%d", i);
        f->component = f->instantiate(name, fmi2CoSimulation, f->guid, NULL, &callbacks,
                                      fmi2False, fmi2False);
        if (f->component == NULL) {
            fprintf(stderr, "%s: fmi2Instantiate returned NULL\n", f->path);
            return 3;
        }
    }
    for (i = 0; i < w.n_starts; i++) {
        struct start_value *start = &w.starts[i];
        struct fmu *f = &w.fmus[start->fmu];
        if (start->is_boolean) {
            CHECK(f->set_boolean(f->component, &start->vr, 1, &start->boolean));
        } else {
            CHECK(f->set_real(f->component, &start->vr, 1, &start->real));
        }
    }
    for (i = 0; i < FMUS; i++) {
        struct fmu *f = &w.fmus[i];
        CHECK(f->setup_experiment(f->component, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        CHECK(f->enter_initialization_mode(f->component));
        CHECK(f->exit_initialization_mode(f->component));
    }

    for (k = 0; k <= w.steps; k++) {
        /* t_k as k·h, not a running sum, as demo/cosim.py does. */
        time = k * w.step_size;
        for (i = 0; i < w.n_connections; i++) {
            struct fmu *from = &w.fmus[w.connections[i].from];
            CHECK(from->get_real(from->component, &w.connections[i].output, 1, &outputs[i]));
        }
        printf("%.17g", time);
        for (i = 0; i < w.n_connections; i++) {
            printf(" %.17g", outputs[i]);
        }
        putchar('\n');
        if (k == w.steps) {
            break;
        }
        /* Jacobi: every input is set from the outputs at t_k before either
         * FMU steps. */
        for (i = 0; i < w.n_connections; i++) {
            struct fmu *to = &w.fmus[w.connections[i].to];
            CHECK(to->set_real(to->component, &w.connections[i].input, 1, &outputs[i]));
        }
        for (i = 0; i < FMUS; i++) {
            CHECK(w.fmus[i].do_step(w.fmus[i].component, time, w.step_size, fmi2True));
        }
    }
    for (i = 0; i < FMUS; i++) {
        CHECK(w.fmus[i].terminate(w.fmus[i].component));
        w.fmus[i].free_instance(w.fmus[i].component);
        fmu_library_close(w.fmus[i].library);
    }
    return 0;
}
