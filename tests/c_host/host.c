/*
 * A minimal non-Python FMI 2.0 co-simulation host: proves an FMU binary loads with
 * dlopen(RTLD_NOW) (every symbol it needs, libm included, resolves), exports every fmi2 function,
 * and runs: instantiate, set up, initialise, set one Real input, step, read one Real output.
 *
 * usage: host LIBRARY GUID [INPUT_VR INPUT_VALUE OUTPUT_VR EXPECTED STEPS STEP_SIZE]
 * Prints "ok" and exits 0 on success; prints the failure and exits 1 otherwise.
 */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static const char *const REQUIRED[] = {
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate", "fmi2FreeInstance",
    "fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Terminate",
    "fmi2Reset", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal",
    "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate",
    "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2EnterEventMode", "fmi2NewDiscreteStates",
    "fmi2EnterContinuousTimeMode", "fmi2CompletedIntegratorStep", "fmi2SetTime", "fmi2SetContinuousStates",
    "fmi2GetDerivatives", "fmi2GetEventIndicators", "fmi2GetContinuousStates",
    "fmi2GetNominalsOfContinuousStates", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
    "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus", "fmi2GetStringStatus",
};

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env;
    fprintf(stderr, "[%s %d %s] %s\n", name, (int)status, category, message);
}

static int fail(const char *what) {
    printf("FAIL: %s\n", what);
    return 1;
}

int main(int argc, char **argv) {
    void *library;
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component component;
    if (argc != 3 && argc != 9) {
        return fail("usage: host LIBRARY GUID [INPUT_VR INPUT_VALUE OUTPUT_VR EXPECTED STEPS STEP_SIZE]");
    }
    library = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (library == NULL) {
        printf("FAIL: dlopen: %s\n", dlerror());
        return 1;
    }
    for (size_t i = 0; i < sizeof REQUIRED / sizeof REQUIRED[0]; i++) {
        if (dlsym(library, REQUIRED[i]) == NULL) {
            printf("FAIL: missing symbol %s\n", REQUIRED[i]);
            return 1;
        }
    }
    {
        /* POSIX guarantees a data pointer from dlsym converts to a function pointer. */
        fmi2InstantiateTYPE *instantiate;
        fmi2SetupExperimentTYPE *setup;
        fmi2EnterInitializationModeTYPE *enter;
        fmi2ExitInitializationModeTYPE *exit_init;
        fmi2SetRealTYPE *set_real;
        fmi2GetRealTYPE *get_real;
        fmi2DoStepTYPE *do_step;
        fmi2TerminateTYPE *terminate;
        fmi2FreeInstanceTYPE *free_instance;
        *(void **)&instantiate = dlsym(library, "fmi2Instantiate");
        *(void **)&setup = dlsym(library, "fmi2SetupExperiment");
        *(void **)&enter = dlsym(library, "fmi2EnterInitializationMode");
        *(void **)&exit_init = dlsym(library, "fmi2ExitInitializationMode");
        *(void **)&set_real = dlsym(library, "fmi2SetReal");
        *(void **)&get_real = dlsym(library, "fmi2GetReal");
        *(void **)&do_step = dlsym(library, "fmi2DoStep");
        *(void **)&terminate = dlsym(library, "fmi2Terminate");
        *(void **)&free_instance = dlsym(library, "fmi2FreeInstance");

        component = instantiate("host", fmi2CoSimulation, argv[2], "", &callbacks, fmi2False, fmi2False);
        if (component == NULL) {
            return fail("fmi2Instantiate returned NULL");
        }
        if (setup(component, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK || enter(component) != fmi2OK ||
            exit_init(component) != fmi2OK) {
            return fail("initialisation");
        }
        if (argc == 9) {
            fmi2ValueReference input = (fmi2ValueReference)strtoul(argv[3], NULL, 10);
            fmi2Real value = strtod(argv[4], NULL);
            fmi2ValueReference output = (fmi2ValueReference)strtoul(argv[5], NULL, 10);
            double expected = strtod(argv[6], NULL), result = NAN;
            int steps = atoi(argv[7]);
            double step_size = strtod(argv[8], NULL);
            if (set_real(component, &input, 1, &value) != fmi2OK) {
                return fail("fmi2SetReal");
            }
            for (int k = 0; k < steps; k++) {
                if (do_step(component, k * step_size, step_size, fmi2True) != fmi2OK) {
                    return fail("fmi2DoStep");
                }
            }
            if (get_real(component, &output, 1, &result) != fmi2OK) {
                return fail("fmi2GetReal");
            }
            if (!(fabs(result - expected) <= 1e-9 * (1.0 + fabs(expected)))) {
                printf("FAIL: output %u is %.17g, expected %.17g\n", output, result, expected);
                return 1;
            }
        }
        if (terminate(component) != fmi2OK) {
            return fail("fmi2Terminate");
        }
        free_instance(component);
    }
    dlclose(library);
    printf("ok\n");
    return 0;
}
