/*
 * The FMI 3.0 co-simulation API, written once for every navcosim FMU.
 *
 * Same model (fmus/<Model>/model.c, see model.h) as the FMI 2.0 glue; only the interface differs.
 * The FMI 3.0 description is derived by the build from the model's FMI 2.0 modelDescription.xml:
 * value reference 0 is the independent variable `time`, the others number the variables in order,
 * and the FMI 2.0 scalars `name[i]` / `name[i,j]` of one array become one Float64 (Int32, Boolean)
 * array variable with Dimensions. The generated `fmi3_variable_table.h` gives, per FMI 3.0 value
 * reference, the type, when it may be set, its name and its elements as the model's own value
 * references (those of the FMI 2.0 description, which model_real/integer/boolean take), so one
 * fmi3GetFloat64/fmi3SetFloat64 moves a whole array.
 *
 * The instance resolves the storage of every element once, at instantiation; an array whose
 * elements are contiguous in the model (VFH's ranges) and not watched is then moved by one memcpy.
 *
 * There is no global or static mutable state: every instance is independent.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "config.h"
#include "fmu_state.h"
#include "model.h"

/* When a variable may be set; the generated table holds one of these per value reference. */
enum VariableAccess {
    ACCESS_UNKNOWN = 0,   /* unused by the FMI 3.0 table: every value reference below the count exists */
    ACCESS_READ_ONLY = 1, /* output, local, calculated parameter, constant, the independent variable */
    ACCESS_FIXED = 2,     /* fixed parameter: settable until initialisation ends */
    ACCESS_ANY_TIME = 3,  /* input or tunable parameter */
};

/* The FMI 3.0 type of a variable; TYPE_INDEPENDENT is `time` (a Float64 the glue holds itself). */
enum VariableType { TYPE_INDEPENDENT = 0, TYPE_FLOAT64 = 1, TYPE_INT32 = 2, TYPE_BOOLEAN = 3 };

typedef struct {
    unsigned char type;   /* enum VariableType */
    unsigned char access; /* enum VariableAccess */
    unsigned first;       /* index of its first element in model_references */
    unsigned count;       /* number of values: 1 for a scalar, the product of the dimensions for an array */
    const char *name;
} VariableInfo;

#include "fmi3_variable_table.h"

static const char *const TYPE_NAMES[] = {"Float64", "Float64", "Int32", "Boolean"};

/* FMI 3.0 co-simulation states without event mode (a bit each, so a function lists the states it accepts). */
enum InstanceState {
    STATE_INSTANTIATED = 1 << 0,
    STATE_INITIALIZATION_MODE = 1 << 1,
    STATE_STEP_MODE = 1 << 2,
    STATE_TERMINATED = 1 << 3,
    STATE_ERROR = 1 << 4,
};
#define STATES_ANY (STATE_INSTANTIATED | STATE_INITIALIZATION_MODE | STATE_STEP_MODE | STATE_TERMINATED | STATE_ERROR)
#define STATES_READABLE (STATE_INITIALIZATION_MODE | STATE_STEP_MODE | STATE_TERMINATED | STATE_ERROR)
#define STATES_WRITABLE (STATE_INSTANTIATED | STATE_INITIALIZATION_MODE | STATE_STEP_MODE)

struct ModelInstance {
    char *instance_name;
    fmi3LogMessageCallback logger;
    fmi3InstanceEnvironment environment;
    int logging_on;
    enum InstanceState state;
    double time;                            /* [s] communication point the instance has reached */
    void *storage[ELEMENT_COUNT];           /* where each element lives in `data` */
    unsigned char one_copy[VARIABLE_COUNT]; /* Float64 elements contiguous and unwatched: one memcpy */
    ModelData data;
};

/* ---------------------------------------------------------------- logging */

static void log_message(ModelInstance *comp, fmi3Status status, const char *category, const char *format,
                        va_list args) {
    char text[1024];
    if (comp == NULL || comp->logger == NULL) {
        return;
    }
    vsnprintf(text, sizeof text, format, args); /* FMI 3.0 passes the message verbatim: no '%' escaping */
    comp->logger(comp->environment, status, category, text);
}

void model_log_error(ModelInstance *comp, const char *format, ...) {
    va_list args;
    va_start(args, format);
    log_message(comp, fmi3Error, "logError", format, args);
    va_end(args);
}

void model_log_info(ModelInstance *comp, const char *format, ...) {
    va_list args;
    if (comp == NULL || !comp->logging_on) {
        return;
    }
    va_start(args, format);
    log_message(comp, fmi3OK, "logInfo", format, args);
    va_end(args);
}

ModelData *model_data(ModelInstance *comp) { return &comp->data; }

static const char *state_name(enum InstanceState state) {
    switch (state) {
    case STATE_INSTANTIATED: return "instantiated";
    case STATE_INITIALIZATION_MODE: return "initialization mode";
    case STATE_STEP_MODE: return "step mode";
    case STATE_TERMINATED: return "terminated";
    default: return "error";
    }
}

/* A call-sequence error leaves the instance's data intact, so the state does not change. */
static int state_allows(ModelInstance *comp, int allowed_states, const char *function) {
    if (comp == NULL) {
        return 0;
    }
    if ((comp->state & allowed_states) == 0) {
        model_log_error(comp, "%s is not allowed in state '%s'", function, state_name(comp->state));
        return 0;
    }
    return 1;
}

static fmi3Status to_fmi3(ModelStatus status) {
    switch (status) {
    case MODEL_OK: return fmi3OK;
    case MODEL_WARNING: return fmi3Warning;
    case MODEL_DISCARD: return fmi3Discard;
    default: return fmi3Error;
    }
}

static fmi3Status unsupported(fmi3Instance instance, const char *function) {
    model_log_error((ModelInstance *)instance, "%s is not supported by this FMU", function);
    return fmi3Error;
}

static int pointer_given(ModelInstance *comp, const void *pointer, const char *function, const char *argument) {
    if (pointer == NULL) {
        model_log_error(comp, "%s: %s is NULL", function, argument);
        return 0;
    }
    return 1;
}

/* ---------------------------------------------------------------- lifecycle */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    ModelInstance *comp = (ModelInstance *)instance;
    (void)nCategories;
    (void)categories;
    if (!state_allows(comp, STATES_ANY, "fmi3SetDebugLogging")) {
        return fmi3Error;
    }
    comp->logging_on = loggingOn;
    return fmi3OK;
}

static void *element_storage(ModelData *data, unsigned type, unsigned model_reference) {
    switch (type) {
    case TYPE_FLOAT64: return model_real(data, model_reference);
    case TYPE_INT32: return model_integer(data, model_reference);
    case TYPE_BOOLEAN: return model_boolean(data, model_reference);
    default: return NULL;
    }
}

/* Resolve where every element is stored and which Float64 variables move by one memcpy. Every
 * variable of the description must have storage in the model: checked here, once per instance, so
 * get and set dereference the pointers without a check per value. */
static int resolve_storage(ModelInstance *comp) {
    for (unsigned vr = 0; vr < VARIABLE_COUNT; vr++) {
        const VariableInfo *variable = &variables[vr];
        int contiguous = 1, watched = 0;
        if (variable->type == TYPE_INDEPENDENT) {
            continue;
        }
        for (unsigned e = 0; e < variable->count; e++) {
            unsigned model_reference = model_references[variable->first + e];
            void *storage = element_storage(&comp->data, variable->type, model_reference);
            if (storage == NULL) {
                model_log_error(comp,
                                "%s variable %s (element %u, model value reference %u) is in "
                                "modelDescription.xml but not in the model",
                                TYPE_NAMES[variable->type], variable->name, e + 1, model_reference);
                return 0;
            }
            comp->storage[variable->first + e] = storage;
            if (variable->type == TYPE_FLOAT64 && (double *)storage != (double *)comp->storage[variable->first] + e) {
                contiguous = 0;
            }
#ifdef MODEL_WATCHES_REAL
            if (variable->type == TYPE_FLOAT64 && MODEL_WATCHES_REAL(model_reference)) {
                watched = 1;
            }
#endif
        }
        comp->one_copy[vr] = (unsigned char)(variable->type == TYPE_FLOAT64 && contiguous && !watched);
    }
    return 1;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    ModelInstance *comp;
    const char *name = instanceName != NULL ? instanceName : "";
    char text[256];
    /* No event mode, no early return and no intermediate update: the FMU has no events and steps
     * synchronously, so these requests need nothing from it (hasEventMode is false). */
    (void)resourcePath, (void)visible, (void)eventModeUsed, (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables, (void)nRequiredIntermediateVariables, (void)intermediateUpdate;
    if (instantiationToken == NULL || strcmp(instantiationToken, MODEL_GUID) != 0) {
        if (logMessage != NULL) {
            snprintf(text, sizeof text, "instantiation token '%s' does not match this FMU's '%s'",
                     instantiationToken != NULL ? instantiationToken : "(null)", MODEL_GUID);
            logMessage(instanceEnvironment, fmi3Error, "logError", text);
        }
        return NULL;
    }
    comp = calloc(1, sizeof *comp);
    if (comp == NULL) {
        return NULL;
    }
    comp->instance_name = malloc(strlen(name) + 1);
    if (comp->instance_name == NULL) {
        free(comp);
        return NULL;
    }
    strcpy(comp->instance_name, name);
    comp->logger = logMessage;
    comp->environment = instanceEnvironment;
    comp->logging_on = loggingOn;
    comp->state = STATE_INSTANTIATED;
    model_set_start_values(&comp->data);
    if (!resolve_storage(comp)) {
        fmi3FreeInstance(comp);
        return NULL;
    }
    return comp;
}

static fmi3Instance not_co_simulation(fmi3InstanceEnvironment environment, fmi3LogMessageCallback logMessage) {
    if (logMessage != NULL) {
        logMessage(environment, fmi3Error, "logError", MODEL_IDENTIFIER " supports co-simulation only");
    }
    return NULL;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    return not_co_simulation(instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    return not_co_simulation(instanceEnvironment, logMessage);
}

void fmi3FreeInstance(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (comp == NULL) {
        return;
    }
    free(comp->instance_name);
    free(comp);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    ModelInstance *comp = (ModelInstance *)instance;
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    if (!state_allows(comp, STATE_INSTANTIATED, "fmi3EnterInitializationMode")) {
        return fmi3Error;
    }
    comp->time = startTime;
    comp->state = STATE_INITIALIZATION_MODE;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    ModelStatus status;
    if (!state_allows(comp, STATE_INITIALIZATION_MODE, "fmi3ExitInitializationMode")) {
        return fmi3Error;
    }
    status = model_initialize(comp, &comp->data);
    if (status == MODEL_ERROR || status == MODEL_DISCARD) {
        comp->state = STATE_ERROR;
        return fmi3Error;
    }
    comp->state = STATE_STEP_MODE; /* without event mode, co-simulation goes straight to step mode */
    return to_fmi3(status);
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (!state_allows(comp, STATE_STEP_MODE, "fmi3Terminate")) {
        return fmi3Error;
    }
    comp->state = STATE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (!state_allows(comp, STATES_ANY, "fmi3Reset")) {
        return fmi3Error;
    }
    /* The storage pointers point into `data`, which stays where it is. */
    memset(&comp->data, 0, sizeof comp->data);
    model_set_start_values(&comp->data);
    comp->state = STATE_INSTANTIATED;
    comp->time = 0.0;
    return fmi3OK;
}

/* ---------------------------------------------------------------- get and set */

/* The variable of value reference `vr` if it has type `type` and may be read (setting = 0) or set
 * (setting = 1) now; otherwise NULL, after logging why not with the variable's name. */
static const VariableInfo *lookup(ModelInstance *comp, fmi3ValueReference vr, unsigned type, int setting,
                                  const char *function) {
    const VariableInfo *variable;
    if (vr >= VARIABLE_COUNT) {
        model_log_error(comp, "%s: unknown value reference %u", function, vr);
        return NULL;
    }
    variable = &variables[vr];
    if (variable->type != type && !(type == TYPE_FLOAT64 && variable->type == TYPE_INDEPENDENT)) {
        model_log_error(comp, "%s: variable %s (value reference %u) is %s, not %s", function, variable->name, vr,
                        TYPE_NAMES[variable->type], TYPE_NAMES[type]);
        return NULL;
    }
    if (!setting || variable->access == ACCESS_ANY_TIME) {
        return variable;
    }
    if (variable->type == TYPE_INDEPENDENT) {
        model_log_error(comp, "the independent variable %s (value reference %u) cannot be set", variable->name, vr);
        return NULL;
    }
    if (variable->access == ACCESS_READ_ONLY) {
        model_log_error(comp, "%s variable %s (value reference %u) cannot be set (output or calculated)",
                        TYPE_NAMES[variable->type], variable->name, vr);
        return NULL;
    }
    if (comp->state == STATE_STEP_MODE) {
        model_log_error(comp, "fixed parameter %s (%s value reference %u) cannot be set after initialisation",
                        variable->name, TYPE_NAMES[variable->type], vr);
        return NULL;
    }
    return variable;
}

/* State, argument and value-reference checks shared by every get and set, before any value moves:
 * each reference must name a variable of `type` accessible now, and `nValues` must be the number
 * of their elements. */
static int call_valid(ModelInstance *comp, const fmi3ValueReference vr[], size_t nvr, const void *values,
                      size_t nValues, unsigned type, int setting, const char *function) {
    size_t total = 0;
    if (!state_allows(comp, setting ? STATES_WRITABLE : STATES_READABLE, function)) {
        return 0;
    }
    if ((nvr > 0 && vr == NULL) || (nValues > 0 && values == NULL)) {
        model_log_error(comp, "%s: NULL array for %zu value references and %zu values", function, nvr, nValues);
        return 0;
    }
    for (size_t i = 0; i < nvr; i++) {
        const VariableInfo *variable = lookup(comp, vr[i], type, setting, function);
        if (variable == NULL) {
            return 0;
        }
        total += variable->count;
    }
    if (total != nValues) {
        model_log_error(comp, "%s: nValues is %zu, the %zu value references have %zu values", function, nValues, nvr,
                        total);
        return 0;
    }
    return 1;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    size_t k = 0;
    if (!call_valid(comp, vr, nvr, values, nValues, TYPE_FLOAT64, 0, "fmi3GetFloat64")) {
        return fmi3Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        const VariableInfo *variable = &variables[vr[i]];
        void *const *storage = &comp->storage[variable->first];
        if (variable->type == TYPE_INDEPENDENT) {
            values[k++] = comp->time;
        } else if (comp->one_copy[vr[i]]) {
            memcpy(&values[k], storage[0], variable->count * sizeof(double));
            k += variable->count;
        } else {
            for (unsigned e = 0; e < variable->count; e++) {
                values[k++] = *(const double *)storage[e];
            }
        }
    }
    return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[],
                        size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    size_t k = 0;
    if (!call_valid(comp, vr, nvr, values, nValues, TYPE_INT32, 0, "fmi3GetInt32")) {
        return fmi3Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        const VariableInfo *variable = &variables[vr[i]];
        for (unsigned e = 0; e < variable->count; e++) {
            values[k++] = (fmi3Int32)*(const int *)comp->storage[variable->first + e];
        }
    }
    return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    size_t k = 0;
    if (!call_valid(comp, vr, nvr, values, nValues, TYPE_BOOLEAN, 0, "fmi3GetBoolean")) {
        return fmi3Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        const VariableInfo *variable = &variables[vr[i]];
        for (unsigned e = 0; e < variable->count; e++) {
            values[k++] = *(const bool *)comp->storage[variable->first + e] ? fmi3True : fmi3False;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    size_t k = 0;
    if (!call_valid(comp, vr, nvr, values, nValues, TYPE_FLOAT64, 1, "fmi3SetFloat64")) {
        return fmi3Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        const VariableInfo *variable = &variables[vr[i]];
        void *const *storage = &comp->storage[variable->first];
        if (comp->one_copy[vr[i]]) {
            memcpy(storage[0], &values[k], variable->count * sizeof(double));
            k += variable->count;
            continue;
        }
        for (unsigned e = 0; e < variable->count; e++, k++) {
            double *element = (double *)storage[e];
#ifdef MODEL_WATCHES_REAL
            /* As the FMI 2.0 glue: a watched element that changes value (NaN to NaN is no change)
             * is reported to the model, element by element, with its model value reference. */
            const unsigned model_reference = model_references[variable->first + e];
            const double previous = *element;
            *element = values[k];
            if (MODEL_WATCHES_REAL(model_reference) &&
                !(previous == values[k] || (isnan(previous) && isnan(values[k])))) {
                model_real_changed(&comp->data, model_reference);
            }
#else
            *element = values[k];
#endif
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[],
                        size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    size_t k = 0;
    if (!call_valid(comp, vr, nvr, values, nValues, TYPE_INT32, 1, "fmi3SetInt32")) {
        return fmi3Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        const VariableInfo *variable = &variables[vr[i]];
        for (unsigned e = 0; e < variable->count; e++) {
            *(int *)comp->storage[variable->first + e] = (int)values[k++];
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    size_t k = 0;
    if (!call_valid(comp, vr, nvr, values, nValues, TYPE_BOOLEAN, 1, "fmi3SetBoolean")) {
        return fmi3Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        const VariableInfo *variable = &variables[vr[i]];
        for (unsigned e = 0; e < variable->count; e++) {
            *(bool *)comp->storage[variable->first + e] = values[k++] != fmi3False;
        }
    }
    return fmi3OK;
}

/* Types this FMU has no variables of: any value reference is unknown, an empty call is fine. */
static fmi3Status no_variables_of_type(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                       int setting, const char *function) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (!state_allows(comp, setting ? STATES_WRITABLE : STATES_READABLE, function)) {
        return fmi3Error;
    }
    if (nvr > 0) {
        if (vr == NULL) {
            model_log_error(comp, "%s: NULL array for %zu value references", function, nvr);
        } else if (vr[0] < VARIABLE_COUNT) {
            model_log_error(comp, "%s: variable %s (value reference %u) is %s", function, variables[vr[0]].name,
                            vr[0], TYPE_NAMES[variables[vr[0]].type]);
        } else {
            model_log_error(comp, "%s: unknown value reference %u", function, vr[0]);
        }
        return fmi3Error;
    }
    return fmi3OK;
}

#define NO_VARIABLES_GET(fmi_type, function)                                                                  \
    fmi3Status function(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi_type values[], \
                        size_t nValues) {                                                                    \
        (void)values, (void)nValues;                                                                         \
        return no_variables_of_type(instance, vr, nvr, 0, #function);                                        \
    }
#define NO_VARIABLES_SET(fmi_type, function)                                                                   \
    fmi3Status function(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,                     \
                        const fmi_type values[], size_t nValues) {                                            \
        (void)values, (void)nValues;                                                                          \
        return no_variables_of_type(instance, vr, nvr, 1, #function);                                         \
    }

NO_VARIABLES_GET(fmi3Float32, fmi3GetFloat32)
NO_VARIABLES_GET(fmi3Int8, fmi3GetInt8)
NO_VARIABLES_GET(fmi3UInt8, fmi3GetUInt8)
NO_VARIABLES_GET(fmi3Int16, fmi3GetInt16)
NO_VARIABLES_GET(fmi3UInt16, fmi3GetUInt16)
NO_VARIABLES_GET(fmi3UInt32, fmi3GetUInt32)
NO_VARIABLES_GET(fmi3Int64, fmi3GetInt64)
NO_VARIABLES_GET(fmi3UInt64, fmi3GetUInt64)
NO_VARIABLES_GET(fmi3String, fmi3GetString)
NO_VARIABLES_SET(fmi3Float32, fmi3SetFloat32)
NO_VARIABLES_SET(fmi3Int8, fmi3SetInt8)
NO_VARIABLES_SET(fmi3UInt8, fmi3SetUInt8)
NO_VARIABLES_SET(fmi3Int16, fmi3SetInt16)
NO_VARIABLES_SET(fmi3UInt16, fmi3SetUInt16)
NO_VARIABLES_SET(fmi3UInt32, fmi3SetUInt32)
NO_VARIABLES_SET(fmi3Int64, fmi3SetInt64)
NO_VARIABLES_SET(fmi3UInt64, fmi3SetUInt64)
NO_VARIABLES_SET(fmi3String, fmi3SetString)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    (void)valueSizes, (void)values, (void)nValues;
    return no_variables_of_type(instance, vr, nvr, 0, "fmi3GetBinary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    (void)valueSizes, (void)values, (void)nValues;
    return no_variables_of_type(instance, vr, nvr, 1, "fmi3SetBinary");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    (void)values;
    return no_variables_of_type(instance, vr, nvr, 0, "fmi3GetClock");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    (void)values;
    return no_variables_of_type(instance, vr, nvr, 1, "fmi3SetClock");
}

/* ---------------------------------------------------------------- co-simulation */

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    ModelInstance *comp = (ModelInstance *)instance;
    fmi3Status status;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!state_allows(comp, STATE_STEP_MODE, "fmi3DoStep")) {
        return fmi3Error;
    }
    if (!(communicationStepSize >= 0.0) || !isfinite(communicationStepSize) || !isfinite(currentCommunicationPoint)) {
        model_log_error(comp, "fmi3DoStep: invalid step t = %g s, h = %g s", currentCommunicationPoint,
                        communicationStepSize);
        return fmi3Error;
    }
    status = to_fmi3(model_do_step(comp, &comp->data, currentCommunicationPoint, communicationStepSize));
    if (status == fmi3Error) {
        comp->state = STATE_ERROR; /* a failure inside the model leaves its data undefined */
    } else if (status <= fmi3Warning) {
        comp->time = currentCommunicationPoint + communicationStepSize;
    }
    /* No events, no early return, and the FMU never asks the importer to stop. */
    if (eventHandlingNeeded != NULL) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation != NULL) *terminateSimulation = fmi3False;
    if (earlyReturn != NULL) *earlyReturn = fmi3False;
    if (lastSuccessfulTime != NULL) *lastSuccessfulTime = comp->time;
    return status;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterStepMode (the FMU has no event mode)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    (void)vr, (void)nvr, (void)orders, (void)values, (void)nValues;
    return unsupported(instance, "fmi3GetOutputDerivatives");
}

/* ---------------------------------------------------------------- FMU state */

static int state_valid(ModelInstance *comp, fmi3FMUState FMUState, const char *function) {
    if (!fmu_state_is_valid((const FmuState *)FMUState, sizeof(ModelData))) {
        model_log_error(comp, "%s: the FMU state is NULL, freed or not from this FMU", function);
        return 0;
    }
    return 1;
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    ModelInstance *comp = (ModelInstance *)instance;
    FmuState *state;
    if (!state_allows(comp, STATES_ANY, "fmi3GetFMUState") ||
        !pointer_given(comp, FMUState, "fmi3GetFMUState", "FMUState")) {
        return fmi3Error;
    }
    /* A non-NULL *FMUState is a state saved before: it is overwritten in place. */
    if (*FMUState != NULL && !state_valid(comp, *FMUState, "fmi3GetFMUState")) {
        return fmi3Error;
    }
    state = *FMUState != NULL ? (FmuState *)*FMUState : fmu_state_new(sizeof(ModelData));
    if (state == NULL) {
        model_log_error(comp, "fmi3GetFMUState: out of memory");
        return fmi3Error;
    }
    fmu_state_save(state, &comp->data, comp->time, (int)comp->state);
    *FMUState = state;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    ModelInstance *comp = (ModelInstance *)instance;
    int instance_state;
    if (!state_allows(comp, STATES_ANY, "fmi3SetFMUState") || !state_valid(comp, FMUState, "fmi3SetFMUState")) {
        return fmi3Error;
    }
    fmu_state_restore((const FmuState *)FMUState, &comp->data, &comp->time, &instance_state);
    comp->state = (enum InstanceState)instance_state;
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (!state_allows(comp, STATES_ANY, "fmi3FreeFMUState")) {
        return fmi3Error;
    }
    if (FMUState == NULL || *FMUState == NULL) {
        return fmi3OK; /* nothing to free */
    }
    if (!state_valid(comp, *FMUState, "fmi3FreeFMUState")) {
        return fmi3Error;
    }
    fmu_state_free((FmuState *)*FMUState);
    *FMUState = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (!state_allows(comp, STATES_ANY, "fmi3SerializedFMUStateSize") ||
        !state_valid(comp, FMUState, "fmi3SerializedFMUStateSize") ||
        !pointer_given(comp, size, "fmi3SerializedFMUStateSize", "size")) {
        return fmi3Error;
    }
    *size = fmu_state_serialized_size(sizeof(ModelData));
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (!state_allows(comp, STATES_ANY, "fmi3SerializeFMUState") ||
        !state_valid(comp, FMUState, "fmi3SerializeFMUState") ||
        !pointer_given(comp, serializedState, "fmi3SerializeFMUState", "serializedState")) {
        return fmi3Error;
    }
    if (size < fmu_state_serialized_size(sizeof(ModelData))) {
        model_log_error(comp, "fmi3SerializeFMUState: buffer of %zu bytes, the state needs %zu", size,
                        fmu_state_serialized_size(sizeof(ModelData)));
        return fmi3Error;
    }
    fmu_state_serialize((const FmuState *)FMUState, 3, MODEL_GUID, serializedState);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    ModelInstance *comp = (ModelInstance *)instance;
    FmuState *state;
    const char *problem;
    if (!state_allows(comp, STATES_ANY, "fmi3DeserializeFMUState") ||
        !pointer_given(comp, serializedState, "fmi3DeserializeFMUState", "serializedState") ||
        !pointer_given(comp, FMUState, "fmi3DeserializeFMUState", "FMUState")) {
        return fmi3Error;
    }
    if (*FMUState != NULL && !state_valid(comp, *FMUState, "fmi3DeserializeFMUState")) {
        return fmi3Error;
    }
    state = *FMUState != NULL ? (FmuState *)*FMUState : fmu_state_new(sizeof(ModelData));
    if (state == NULL) {
        model_log_error(comp, "fmi3DeserializeFMUState: out of memory");
        return fmi3Error;
    }
    problem = fmu_state_deserialize(state, 3, MODEL_GUID, serializedState, size);
    if (problem != NULL) {
        if (*FMUState == NULL) {
            fmu_state_free(state);
        }
        model_log_error(comp, "fmi3DeserializeFMUState: %s", problem);
        return fmi3Error;
    }
    *FMUState = state;
    return fmi3OK;
}

/* ---------------------------------------------------------------- not supported (FMI 3 requires the symbols) */

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterEventMode (the FMU has no event mode)");
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference, (void)nDependencies;
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent, (void)elementIndicesOfDependent, (void)independents, (void)elementIndicesOfIndependents;
    (void)dependencyKinds, (void)nDependencies;
    return unsupported(instance, "fmi3GetVariableDependencies");
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    return unsupported(instance, "fmi3GetDirectionalDerivative");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    return unsupported(instance, "fmi3GetAdjointDerivative");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterConfigurationMode (the FMU has no structural parameters)");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3ExitConfigurationMode (the FMU has no structural parameters)");
}

/* Clocks: the FMU has none. */

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    (void)vr, (void)nvr, (void)intervals, (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalDecimal (the FMU has no clocks)");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions, (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalFraction (the FMU has no clocks)");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    (void)vr, (void)nvr, (void)shifts;
    return unsupported(instance, "fmi3GetShiftDecimal (the FMU has no clocks)");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return unsupported(instance, "fmi3GetShiftFraction (the FMU has no clocks)");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    (void)vr, (void)nvr, (void)intervals;
    return unsupported(instance, "fmi3SetIntervalDecimal (the FMU has no clocks)");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return unsupported(instance, "fmi3SetIntervalFraction (the FMU has no clocks)");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr, (void)nvr, (void)shifts;
    return unsupported(instance, "fmi3SetShiftDecimal (the FMU has no clocks)");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return unsupported(instance, "fmi3SetShiftFraction (the FMU has no clocks)");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return unsupported(instance, "fmi3EvaluateDiscreteStates (the FMU has no event mode)");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate, (void)terminateSimulation, (void)nominalsOfContinuousStatesChanged;
    (void)valuesOfContinuousStatesChanged, (void)nextEventTimeDefined, (void)nextEventTime;
    return unsupported(instance, "fmi3UpdateDiscreteStates (the FMU has no event mode)");
}

/* Model-exchange functions: this is a co-simulation-only FMU. */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterContinuousTimeMode (model exchange)");
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
    return unsupported(instance, "fmi3CompletedIntegratorStep (model exchange)");
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    (void)time;
    return unsupported(instance, "fmi3SetTime (model exchange)");
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates, (void)nContinuousStates;
    return unsupported(instance, "fmi3SetContinuousStates (model exchange)");
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    (void)derivatives, (void)nContinuousStates;
    return unsupported(instance, "fmi3GetContinuousStateDerivatives (model exchange)");
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    (void)eventIndicators, (void)nEventIndicators;
    return unsupported(instance, "fmi3GetEventIndicators (model exchange)");
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
    (void)continuousStates, (void)nContinuousStates;
    return unsupported(instance, "fmi3GetContinuousStates (model exchange)");
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    (void)nominals, (void)nContinuousStates;
    return unsupported(instance, "fmi3GetNominalsOfContinuousStates (model exchange)");
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    (void)nEventIndicators;
    return unsupported(instance, "fmi3GetNumberOfEventIndicators (model exchange)");
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    (void)nContinuousStates;
    return unsupported(instance, "fmi3GetNumberOfContinuousStates (model exchange)");
}

/* Scheduled execution: not supported. */

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference, (void)activationTime;
    return unsupported(instance, "fmi3ActivateModelPartition (scheduled execution)");
}
