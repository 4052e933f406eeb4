/* A minimal FMI 2.0 co-simulation importer in C, as tools written in C load
 * an FMU binary: dlopen (LoadLibrary on Windows), every function resolved
 * through the official typedefs of fmi2FunctionTypes.h, then instantiate,
 * initialize, step, save and restore the FMU state (in memory and
 * serialized), terminate, free. Built with -Wall -Wextra -Werror -pedantic
 * by tests/test_c_importer.py (gcc) and tests/test_windows_binaries.py
 * (x86_64-w64-mingw32-gcc, run under wine).
 *
 * usage: importer <library> <guid> <input vr> <input value> <output vr>
 * prints the output after 100 steps of 1e-4 s; exits non-zero on any
 * status other than fmi2OK, a missing symbol, or a state that does not
 * restore bit for bit. */

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2FunctionTypes.h"
#include "fmu_library.h"

#define STEPS 100
#define SAVE_AT 50
#define STEP_SIZE 1e-4

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

/* Resolves `name` into a pointer of the official type name##TYPE. */
#define RESOLVE(name)                                                   \
    name##TYPE *name = (name##TYPE *)fmu_library_symbol(library, #name); \
    if (name == NULL) {                                                 \
        fprintf(stderr, "missing symbol %s\n", #name);                  \
        return 2;                                                       \
    }

#define CHECK(call)                                                     \
    do {                                                                \
        fmi2Status status_ = (call);                                    \
        if (status_ != fmi2OK) {                                        \
            fprintf(stderr, "%s returned %d\n", #call, (int)status_);   \
            return 3;                                                   \
        }                                                               \
    } while (0)

int main(int argc, char **argv) {
    fmu_library library;
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c;
    fmi2ValueReference input, output;
    fmi2Real value, time = 0.0, y, first[STEPS], again[STEPS];
    fmi2FMUstate state = NULL, restored = NULL;
    size_t size = 0;
    char *bytes;
    int k;

    if (argc != 6) {
        fprintf(stderr, "usage: %s <library> <guid> <input vr> <input value> <output vr>\n",
                argv[0]);
        return 1;
    }
    library = fmu_library_open(argv[1]);
    if (library == NULL) {
        return 2;
    }
    input = (fmi2ValueReference)strtoul(argv[3], NULL, 10);
    value = strtod(argv[4], NULL);
    output = (fmi2ValueReference)strtoul(argv[5], NULL, 10);

    {
        /* Every function of the common and co-simulation API, model-exchange
         * ones excluded (a co-simulation-only FMU need not export them). */
        RESOLVE(fmi2GetTypesPlatform)
        RESOLVE(fmi2GetVersion)
        RESOLVE(fmi2SetDebugLogging)
        RESOLVE(fmi2Instantiate)
        RESOLVE(fmi2FreeInstance)
        RESOLVE(fmi2SetupExperiment)
        RESOLVE(fmi2EnterInitializationMode)
        RESOLVE(fmi2ExitInitializationMode)
        RESOLVE(fmi2Terminate)
        RESOLVE(fmi2Reset)
        RESOLVE(fmi2GetReal)
        RESOLVE(fmi2GetInteger)
        RESOLVE(fmi2GetBoolean)
        RESOLVE(fmi2GetString)
        RESOLVE(fmi2SetReal)
        RESOLVE(fmi2SetInteger)
        RESOLVE(fmi2SetBoolean)
        RESOLVE(fmi2SetString)
        RESOLVE(fmi2GetFMUstate)
        RESOLVE(fmi2SetFMUstate)
        RESOLVE(fmi2FreeFMUstate)
        RESOLVE(fmi2SerializedFMUstateSize)
        RESOLVE(fmi2SerializeFMUstate)
        RESOLVE(fmi2DeSerializeFMUstate)
        RESOLVE(fmi2GetDirectionalDerivative)
        RESOLVE(fmi2SetRealInputDerivatives)
        RESOLVE(fmi2GetRealOutputDerivatives)
        RESOLVE(fmi2DoStep)
        RESOLVE(fmi2CancelStep)
        RESOLVE(fmi2GetStatus)
        RESOLVE(fmi2GetRealStatus)
        RESOLVE(fmi2GetIntegerStatus)
        RESOLVE(fmi2GetBooleanStatus)
        RESOLVE(fmi2GetStringStatus)

        if (strcmp(fmi2GetVersion(), "2.0") != 0 || strcmp(fmi2GetTypesPlatform(), "default") != 0) {
            fprintf(stderr, "unexpected version or types platform\n");
            return 3;
        }
        c = fmi2Instantiate("c-importer", fmi2CoSimulation, argv[2], NULL, &callbacks, fmi2False,
                            fmi2False);
        if (c == NULL) {
            fprintf(stderr, "fmi2Instantiate returned NULL\n");
            return 3;
        }
        CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        CHECK(fmi2EnterInitializationMode(c));
        CHECK(fmi2ExitInitializationMode(c));
        CHECK(fmi2SetReal(c, &input, 1, &value));
        for (k = 0; k < STEPS; k++) {
            if (k == SAVE_AT) {
                CHECK(fmi2GetFMUstate(c, &state));
            }
            CHECK(fmi2DoStep(c, time, STEP_SIZE, fmi2True));
            time += STEP_SIZE;
            CHECK(fmi2GetReal(c, &output, 1, &first[k]));
        }
        /* Back to the saved point, in memory, and the same steps again. */
        CHECK(fmi2SetFMUstate(c, state));
        time = SAVE_AT * STEP_SIZE;
        for (k = SAVE_AT; k < STEPS; k++) {
            CHECK(fmi2DoStep(c, time, STEP_SIZE, fmi2True));
            time += STEP_SIZE;
            CHECK(fmi2GetReal(c, &output, 1, &again[k]));
            if (memcmp(&again[k], &first[k], sizeof(fmi2Real)) != 0) {
                fprintf(stderr, "step %d after fmi2SetFMUstate: %.17g, first run %.17g\n", k,
                        again[k], first[k]);
                return 4;
            }
        }
        /* The same through the serialized bytes. */
        CHECK(fmi2SerializedFMUstateSize(c, state, &size));
        bytes = malloc(size);
        if (bytes == NULL) {
            return 5;
        }
        CHECK(fmi2SerializeFMUstate(c, state, bytes, size));
        CHECK(fmi2DeSerializeFMUstate(c, bytes, size, &restored));
        free(bytes);
        CHECK(fmi2SetFMUstate(c, restored));
        time = SAVE_AT * STEP_SIZE;
        for (k = SAVE_AT; k < STEPS; k++) {
            CHECK(fmi2DoStep(c, time, STEP_SIZE, fmi2True));
            time += STEP_SIZE;
            CHECK(fmi2GetReal(c, &output, 1, &y));
            if (memcmp(&y, &first[k], sizeof(fmi2Real)) != 0) {
                fprintf(stderr, "step %d after deserializing: %.17g, first run %.17g\n", k, y,
                        first[k]);
                return 4;
            }
        }
        CHECK(fmi2FreeFMUstate(c, &state));
        CHECK(fmi2FreeFMUstate(c, &restored));
        CHECK(fmi2Terminate(c));
        fmi2FreeInstance(c);
        printf("%.17g\n", first[STEPS - 1]);
    }
    fmu_library_close(library);
    return 0;
}
