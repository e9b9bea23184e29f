/*
 * The FMI 2.0 co-simulation API, written once for every navcosim FMU.
 *
 * The glue owns the instance lifecycle, the FMI state machine, logging and get/set with their
 * value-reference checks; the model (fmus/<Model>/model.c, see model.h) owns only its maths and
 * says where each variable is stored. This file holds nothing of a model: it reaches the model's
 * identity, data size and generated variable table (per value reference and type, whether the
 * variable exists, its name and when it may be set, from the model's modelDescription.xml, the
 * single source of the variable list) through `fmi2_model` (fmi2_model.h), which the generated
 * `model_binding.h` defines in the model's model.c. So the build compiles it once for every FMU.
 *
 * FMU state (get/set/free, serialise/deserialise) is a copy of the instance's model data, time and
 * state-machine position (fmu_state.c, shared with the FMI 3.0 glue).
 *
 * There is no global or static mutable state: every instance is independent.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmi2_model.h"
#include "fmu_state.h"
#include "model.h"

#define REAL_VARIABLES (&fmi2_model.real)
#define INTEGER_VARIABLES (&fmi2_model.integer)
#define BOOLEAN_VARIABLES (&fmi2_model.boolean)

/* FMI 2.0 co-simulation states (a bit each, so a function lists the states it accepts). */
enum InstanceState {
    STATE_INSTANTIATED = 1 << 0,
    STATE_INITIALIZATION_MODE = 1 << 1,
    STATE_STEP_COMPLETE = 1 << 2,
    STATE_TERMINATED = 1 << 3,
    STATE_ERROR = 1 << 4,
};
#define STATES_ANY (STATE_INSTANTIATED | STATE_INITIALIZATION_MODE | STATE_STEP_COMPLETE | STATE_TERMINATED | STATE_ERROR)
#define STATES_READABLE (STATE_INITIALIZATION_MODE | STATE_STEP_COMPLETE | STATE_TERMINATED | STATE_ERROR)
#define STATES_WRITABLE (STATE_INSTANTIATED | STATE_INITIALIZATION_MODE | STATE_STEP_COMPLETE)

struct ModelInstance {
    char *instance_name;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment environment;
    int logging_on;
    enum InstanceState state;
    double time; /* [s] communication point the instance has reached */
    ModelData *data; /* fmi2_model.data_size bytes */
};

/* ---------------------------------------------------------------- logging */

static void log_message(ModelInstance *comp, fmi2Status status, const char *category, const char *format,
                        va_list args) {
    char text[1024];
    char escaped[2 * sizeof text];
    size_t j = 0;
    if (comp == NULL || comp->logger == NULL) {
        return;
    }
    vsnprintf(text, sizeof text, format, args);
    /* The logger treats the message as a printf format: escape '%' so text passes verbatim. */
    for (size_t i = 0; text[i] != '\0' && j + 2 < sizeof escaped; i++) {
        if (text[i] == '%') {
            escaped[j++] = '%';
        }
        escaped[j++] = text[i];
    }
    escaped[j] = '\0';
    comp->logger(comp->environment, comp->instance_name, status, category, escaped);
}

void model_log_error(ModelInstance *comp, const char *format, ...) {
    va_list args;
    va_start(args, format);
    log_message(comp, fmi2Error, "logError", format, args);
    va_end(args);
}

void model_log_info(ModelInstance *comp, const char *format, ...) {
    va_list args;
    if (comp == NULL || !comp->logging_on) {
        return;
    }
    va_start(args, format);
    log_message(comp, fmi2OK, "logInfo", format, args);
    va_end(args);
}

ModelData *model_data(ModelInstance *comp) { return comp->data; }

static const char *state_name(enum InstanceState state) {
    switch (state) {
    case STATE_INSTANTIATED: return "instantiated";
    case STATE_INITIALIZATION_MODE: return "initialization mode";
    case STATE_STEP_COMPLETE: return "step complete";
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

static fmi2Status to_fmi2(ModelStatus status) {
    switch (status) {
    case MODEL_OK: return fmi2OK;
    case MODEL_WARNING: return fmi2Warning;
    case MODEL_DISCARD: return fmi2Discard;
    default: return fmi2Error;
    }
}

/* A failure inside the model leaves its data undefined: the instance enters the error state. */
static fmi2Status model_result(ModelInstance *comp, ModelStatus status) {
    if (status == MODEL_ERROR) {
        comp->state = STATE_ERROR;
    }
    return to_fmi2(status);
}

static fmi2Status unsupported(fmi2Component c, const char *function) {
    model_log_error((ModelInstance *)c, "%s is not supported by this FMU", function);
    return fmi2Error;
}

/* ---------------------------------------------------------------- lifecycle */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)nCategories;
    (void)categories;
    if (!state_allows(comp, STATES_ANY, "fmi2SetDebugLogging")) {
        return fmi2Error;
    }
    comp->logging_on = loggingOn;
    return fmi2OK;
}

static int missing_storage(ModelInstance *comp, const VariableTable *table, unsigned vr) {
    model_log_error(comp, "%s variable %s (value reference %u) is in modelDescription.xml but not in the model",
                    table->type_name, table->names[vr], vr);
    return 0;
}

/* Every variable of modelDescription.xml has storage in the model: checked once per instance, so
 * get and set dereference the model's pointers without a check per value. (The loops run over the
 * arrays, never empty, as a type without variables has TABLE_SIZE 0.) */
static int storage_matches_description(ModelInstance *comp) {
    for (unsigned vr = 0; vr < fmi2_model.real.size; vr++) {
        if (fmi2_model.real.access[vr] != ACCESS_UNKNOWN && model_real(comp->data, vr) == NULL) {
            return missing_storage(comp, REAL_VARIABLES, vr);
        }
    }
    for (unsigned vr = 0; vr < fmi2_model.integer.size; vr++) {
        if (fmi2_model.integer.access[vr] != ACCESS_UNKNOWN && model_integer(comp->data, vr) == NULL) {
            return missing_storage(comp, INTEGER_VARIABLES, vr);
        }
    }
    for (unsigned vr = 0; vr < fmi2_model.boolean.size; vr++) {
        if (fmi2_model.boolean.access[vr] != ACCESS_UNKNOWN && model_boolean(comp->data, vr) == NULL) {
            return missing_storage(comp, BOOLEAN_VARIABLES, vr);
        }
    }
    return 1;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    ModelInstance *comp;
    const char *name = instanceName != NULL ? instanceName : "";
    fmi2CallbackLogger logger = functions != NULL ? functions->logger : NULL;
    void *environment = functions != NULL ? functions->componentEnvironment : NULL;
    (void)fmuResourceLocation;
    (void)visible;
    if (fmuType != fmi2CoSimulation) {
        if (logger != NULL) {
            logger(environment, name, fmi2Error, "logError", "%s supports co-simulation only", fmi2_model.identifier);
        }
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, fmi2_model.guid) != 0) {
        if (logger != NULL) {
            logger(environment, name, fmi2Error, "logError", "GUID '%s' does not match this FMU's '%s'",
                   fmuGUID != NULL ? fmuGUID : "(null)", fmi2_model.guid);
        }
        return NULL;
    }
    comp = calloc(1, sizeof *comp);
    if (comp == NULL) {
        return NULL;
    }
    comp->instance_name = malloc(strlen(name) + 1);
    comp->data = calloc(1, fmi2_model.data_size);
    if (comp->instance_name == NULL || comp->data == NULL) {
        free(comp->instance_name);
        free(comp->data);
        free(comp);
        return NULL;
    }
    strcpy(comp->instance_name, name);
    comp->logger = logger;
    comp->environment = environment;
    comp->logging_on = loggingOn;
    comp->state = STATE_INSTANTIATED;
    model_set_start_values(comp->data);
    if (!storage_matches_description(comp)) {
        fmi2FreeInstance(comp);
        return NULL;
    }
    return comp;
}

void fmi2FreeInstance(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (comp == NULL) {
        return;
    }
    free(comp->instance_name);
    free(comp->data);
    free(comp);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    if (!state_allows(comp, STATE_INSTANTIATED, "fmi2SetupExperiment")) {
        return fmi2Error;
    }
    comp->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!state_allows(comp, STATE_INSTANTIATED, "fmi2EnterInitializationMode")) {
        return fmi2Error;
    }
    comp->state = STATE_INITIALIZATION_MODE;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    ModelStatus status;
    if (!state_allows(comp, STATE_INITIALIZATION_MODE, "fmi2ExitInitializationMode")) {
        return fmi2Error;
    }
    status = model_initialize(comp, comp->data);
    if (status == MODEL_ERROR || status == MODEL_DISCARD) {
        comp->state = STATE_ERROR;
        return fmi2Error;
    }
    comp->state = STATE_STEP_COMPLETE;
    return to_fmi2(status);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!state_allows(comp, STATE_STEP_COMPLETE, "fmi2Terminate")) {
        return fmi2Error;
    }
    comp->state = STATE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!state_allows(comp, STATES_ANY, "fmi2Reset")) {
        return fmi2Error;
    }
    memset(comp->data, 0, fmi2_model.data_size);
    model_set_start_values(comp->data);
    comp->state = STATE_INSTANTIATED;
    comp->time = 0.0;
    return fmi2OK;
}

/* ---------------------------------------------------------------- get and set */

/* Why a value reference may not be accessed, logged with the variable's name when it exists;
 * returns 1 when it may be after all (a fixed parameter before initialisation ends). */
static int access_allowed_slow(ModelInstance *comp, const VariableTable *table, fmi2ValueReference vr, int access) {
    if (access == ACCESS_UNKNOWN) {
        model_log_error(comp, "unknown %s value reference %u", table->type_name, vr);
        return 0;
    }
    if (access == ACCESS_READ_ONLY) {
        model_log_error(comp, "%s variable %s (value reference %u) cannot be set (output or calculated)",
                        table->type_name, table->names[vr], vr);
        return 0;
    }
    if (comp->state == STATE_STEP_COMPLETE) {
        model_log_error(comp, "fixed parameter %s (%s value reference %u) cannot be set after initialisation",
                        table->names[vr], table->type_name, vr);
        return 0;
    }
    return 1;
}

/* Check one value reference against the generated table before the model's storage is touched.
 * Inline with the common case (an existing variable read, an input set) first: VFH sets 1441
 * values a step. */
static inline int may_access(ModelInstance *comp, const VariableTable *table, fmi2ValueReference vr, int setting) {
    int access = vr < table->size ? table->access[vr] : ACCESS_UNKNOWN;
    if (access == ACCESS_ANY_TIME || (!setting && access != ACCESS_UNKNOWN)) {
        return 1;
    }
    return access_allowed_slow(comp, table, vr, setting ? access : ACCESS_UNKNOWN);
}

static int arguments_valid(ModelInstance *comp, const void *vr, size_t nvr, const void *value,
                           const char *function) {
    if (nvr > 0 && (vr == NULL || value == NULL)) {
        model_log_error(comp, "%s: NULL array for %zu values", function, nvr);
        return 0;
    }
    return 1;
}

/* State and argument checks shared by every get (setting = 0) and set (setting = 1) function. */
static int call_valid(ModelInstance *comp, const void *vr, size_t nvr, const void *value, const char *function,
                      int setting) {
    return state_allows(comp, setting ? STATES_WRITABLE : STATES_READABLE, function) &&
           arguments_valid(comp, vr, nvr, value, function);
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!call_valid(comp, vr, nvr, value, "fmi2GetReal", 0)) {
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (!may_access(comp, REAL_VARIABLES, vr[i], 0)) {
            return fmi2Error;
        }
        const double *variable = model_real(comp->data, vr[i]);
        value[i] = *variable;
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!call_valid(comp, vr, nvr, value, "fmi2GetInteger", 0)) {
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (!may_access(comp, INTEGER_VARIABLES, vr[i], 0)) {
            return fmi2Error;
        }
        const int *variable = model_integer(comp->data, vr[i]);
        value[i] = *variable;
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!call_valid(comp, vr, nvr, value, "fmi2GetBoolean", 0)) {
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (!may_access(comp, BOOLEAN_VARIABLES, vr[i], 0)) {
            return fmi2Error;
        }
        const bool *variable = model_boolean(comp->data, vr[i]);
        value[i] = *variable ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)vr;
    (void)value;
    if (!state_allows(comp, STATES_READABLE, "fmi2GetString")) {
        return fmi2Error;
    }
    if (nvr > 0) {
        model_log_error(comp, "unknown String value reference %u (this FMU has no String variables)", vr[0]);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    const unsigned char *watched = fmi2_model.real_watched;
    if (!call_valid(comp, vr, nvr, value, "fmi2SetReal", 1)) {
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (!may_access(comp, REAL_VARIABLES, vr[i], 1)) {
            return fmi2Error;
        }
        double *variable = model_real(comp->data, vr[i]);
        if (watched == NULL) {
            *variable = value[i];
            continue;
        }
        const double previous = *variable; /* store first, then test: the faster order for VFH's 1441 values */
        *variable = value[i];
        if (watched[vr[i]] && !(previous == value[i] || (isnan(previous) && isnan(value[i])))) {
            fmi2_model.real_changed(comp->data, vr[i]);
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!call_valid(comp, vr, nvr, value, "fmi2SetInteger", 1)) {
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (!may_access(comp, INTEGER_VARIABLES, vr[i], 1)) {
            return fmi2Error;
        }
        int *variable = model_integer(comp->data, vr[i]);
        *variable = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!call_valid(comp, vr, nvr, value, "fmi2SetBoolean", 1)) {
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (!may_access(comp, BOOLEAN_VARIABLES, vr[i], 1)) {
            return fmi2Error;
        }
        bool *variable = model_boolean(comp->data, vr[i]);
        *variable = value[i] != fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)value;
    if (!state_allows(comp, STATES_WRITABLE, "fmi2SetString")) {
        return fmi2Error;
    }
    if (nvr > 0) {
        model_log_error(comp, "unknown String value reference %u (this FMU has no String variables)", vr[0]);
        return fmi2Error;
    }
    return fmi2OK;
}

/* ---------------------------------------------------------------- co-simulation */

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    ModelInstance *comp = (ModelInstance *)c;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!state_allows(comp, STATE_STEP_COMPLETE, "fmi2DoStep")) {
        return fmi2Error;
    }
    if (!(communicationStepSize >= 0.0) || !isfinite(communicationStepSize) || !isfinite(currentCommunicationPoint)) {
        model_log_error(comp, "fmi2DoStep: invalid step t = %g s, h = %g s", currentCommunicationPoint,
                        communicationStepSize);
        return fmi2Error;
    }
    {
        fmi2Status status = model_result(
            comp, model_do_step(comp, comp->data, currentCommunicationPoint, communicationStepSize));
        if (status <= fmi2Warning) {
            comp->time = currentCommunicationPoint + communicationStepSize;
        }
        return status;
    }
}

fmi2Status fmi2CancelStep(fmi2Component c) { return unsupported(c, "fmi2CancelStep (steps are synchronous)"); }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s;
    (void)value;
    return unsupported(c, "fmi2GetStatus (steps are synchronous)");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!state_allows(comp, STATES_READABLE, "fmi2GetRealStatus")) {
        return fmi2Error;
    }
    if (s != fmi2LastSuccessfulTime || value == NULL) {
        model_log_error(comp, "fmi2GetRealStatus supports fmi2LastSuccessfulTime only");
        return fmi2Error;
    }
    *value = comp->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s;
    (void)value;
    return unsupported(c, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!state_allows(comp, STATES_READABLE, "fmi2GetBooleanStatus")) {
        return fmi2Error;
    }
    if (s != fmi2Terminated || value == NULL) {
        model_log_error(comp, "fmi2GetBooleanStatus supports fmi2Terminated only");
        return fmi2Error;
    }
    *value = fmi2False; /* the FMU never asks the master to stop */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s;
    (void)value;
    return unsupported(c, "fmi2GetStringStatus");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr, (void)nvr, (void)order, (void)value;
    return unsupported(c, "fmi2SetRealInputDerivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr, (void)nvr, (void)order, (void)value;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}

/* ---------------------------------------------------------------- FMU state */

/* A state saved by fmi2GetFMUstate: model data, time and state-machine position (fmu_state.c). */
static int state_valid(ModelInstance *comp, fmi2FMUstate FMUstate, const char *function) {
    if (!fmu_state_is_valid((const FmuState *)FMUstate, fmi2_model.data_size)) {
        model_log_error(comp, "%s: the FMU state is NULL, freed or not from this FMU", function);
        return 0;
    }
    return 1;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    ModelInstance *comp = (ModelInstance *)c;
    FmuState *state;
    if (!state_allows(comp, STATES_ANY, "fmi2GetFMUstate") ||
        !arguments_valid(comp, FMUstate, 1, FMUstate, "fmi2GetFMUstate")) {
        return fmi2Error;
    }
    /* A non-NULL *FMUstate is a state saved before: it is overwritten in place. */
    if (*FMUstate != NULL && !state_valid(comp, *FMUstate, "fmi2GetFMUstate")) {
        return fmi2Error;
    }
    state = *FMUstate != NULL ? (FmuState *)*FMUstate : fmu_state_new(fmi2_model.data_size);
    if (state == NULL) {
        model_log_error(comp, "fmi2GetFMUstate: out of memory");
        return fmi2Error;
    }
    fmu_state_save(state, comp->data, comp->time, (int)comp->state);
    *FMUstate = state;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    ModelInstance *comp = (ModelInstance *)c;
    int instance_state;
    if (!state_allows(comp, STATES_ANY, "fmi2SetFMUstate") || !state_valid(comp, FMUstate, "fmi2SetFMUstate")) {
        return fmi2Error;
    }
    fmu_state_restore((const FmuState *)FMUstate, comp->data, &comp->time, &instance_state);
    comp->state = (enum InstanceState)instance_state;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!state_allows(comp, STATES_ANY, "fmi2FreeFMUstate")) {
        return fmi2Error;
    }
    if (FMUstate == NULL || *FMUstate == NULL) {
        return fmi2OK; /* nothing to free */
    }
    if (!state_valid(comp, *FMUstate, "fmi2FreeFMUstate")) {
        return fmi2Error;
    }
    fmu_state_free((FmuState *)*FMUstate);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!state_allows(comp, STATES_ANY, "fmi2SerializedFMUstateSize") ||
        !state_valid(comp, FMUstate, "fmi2SerializedFMUstateSize") ||
        !arguments_valid(comp, size, 1, size, "fmi2SerializedFMUstateSize")) {
        return fmi2Error;
    }
    *size = fmu_state_serialized_size(fmi2_model.data_size);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    ModelInstance *comp = (ModelInstance *)c;
    if (!state_allows(comp, STATES_ANY, "fmi2SerializeFMUstate") ||
        !state_valid(comp, FMUstate, "fmi2SerializeFMUstate") ||
        !arguments_valid(comp, serializedState, 1, serializedState, "fmi2SerializeFMUstate")) {
        return fmi2Error;
    }
    if (size < fmu_state_serialized_size(fmi2_model.data_size)) {
        model_log_error(comp, "fmi2SerializeFMUstate: buffer of %zu bytes, the state needs %zu", size,
                        fmu_state_serialized_size(fmi2_model.data_size));
        return fmi2Error;
    }
    fmu_state_serialize((const FmuState *)FMUstate, 2, fmi2_model.guid, (unsigned char *)serializedState);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    ModelInstance *comp = (ModelInstance *)c;
    FmuState *state;
    const char *problem;
    if (!state_allows(comp, STATES_ANY, "fmi2DeSerializeFMUstate") ||
        !arguments_valid(comp, serializedState, 1, FMUstate, "fmi2DeSerializeFMUstate")) {
        return fmi2Error;
    }
    if (*FMUstate != NULL && !state_valid(comp, *FMUstate, "fmi2DeSerializeFMUstate")) {
        return fmi2Error;
    }
    state = *FMUstate != NULL ? (FmuState *)*FMUstate : fmu_state_new(fmi2_model.data_size);
    if (state == NULL) {
        model_log_error(comp, "fmi2DeSerializeFMUstate: out of memory");
        return fmi2Error;
    }
    problem = fmu_state_deserialize(state, 2, fmi2_model.guid, (const unsigned char *)serializedState, size);
    if (problem != NULL) {
        if (*FMUstate == NULL) {
            fmu_state_free(state);
        }
        model_log_error(comp, "fmi2DeSerializeFMUstate: %s", problem);
        return fmi2Error;
    }
    *FMUstate = state;
    return fmi2OK;
}

/* ---------------------------------------------------------------- not supported (FMI 2 requires the symbols) */

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    return unsupported(c, "fmi2GetDirectionalDerivative");
}

/* Model-exchange functions: this is a co-simulation-only FMU. */

fmi2Status fmi2EnterEventMode(fmi2Component c) { return unsupported(c, "fmi2EnterEventMode (model exchange)"); }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    (void)eventInfo;
    return unsupported(c, "fmi2NewDiscreteStates (model exchange)");
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    return unsupported(c, "fmi2EnterContinuousTimeMode (model exchange)");
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
    return unsupported(c, "fmi2CompletedIntegratorStep (model exchange)");
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    (void)time;
    return unsupported(c, "fmi2SetTime (model exchange)");
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    (void)x, (void)nx;
    return unsupported(c, "fmi2SetContinuousStates (model exchange)");
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    (void)derivatives, (void)nx;
    return unsupported(c, "fmi2GetDerivatives (model exchange)");
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators, (void)ni;
    return unsupported(c, "fmi2GetEventIndicators (model exchange)");
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    (void)x, (void)nx;
    return unsupported(c, "fmi2GetContinuousStates (model exchange)");
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    (void)x_nominal, (void)nx;
    return unsupported(c, "fmi2GetNominalsOfContinuousStates (model exchange)");
}
