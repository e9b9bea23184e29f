/*
 * Contract between the glue (written once per FMI version, in fmus/common/: fmi2_glue.c and
 * fmi3_glue.c) and each model (fmus/<Model>/model.c + config.h). The glue owns the FMI API, the
 * instance lifecycle and state machine, logging, FMU state and get/set of variables by value
 * reference; a model holds only its maths and the storage of its variables. One model builds both
 * FMI versions.
 *
 * Value references here are the model's own, those of its FMI 2.0 modelDescription.xml (unique per
 * type). The FMI 3.0 glue maps its own value references (arrays included) onto them.
 *
 * `struct ModelData` holds values only, no pointers and no handles: FMU state (get/set,
 * serialise) is a byte copy of it (fmu_state.c).
 *
 * Each model folder provides:
 *   config.h           MODEL_IDENTIFIER, MODEL_GUID, an enum of value references,
 *                      `struct ModelData { ... }` (parameters, inputs, outputs, state) and,
 *                      when the model has the hook below, `#define MODEL_WATCHES_REAL(vr)`
 *   model.c            the functions declared below
 *   modelDescription.xml  the variable list (value references match the enum)
 */
#ifndef NAVCOSIM_MODEL_H
#define NAVCOSIM_MODEL_H

#include <stdbool.h>
#include <stddef.h>

typedef enum { MODEL_OK = 0, MODEL_WARNING = 1, MODEL_DISCARD = 2, MODEL_ERROR = 3 } ModelStatus;

typedef struct ModelData ModelData; /* defined by each model's config.h */
typedef struct ModelInstance ModelInstance; /* defined by the glue */

/* Provided by the glue: log through the FMU's logger callback (category "logError" for errors). */
void model_log_error(ModelInstance *comp, const char *format, ...);
void model_log_info(ModelInstance *comp, const char *format, ...);
/* Provided by the glue: the model's data of this instance. */
ModelData *model_data(ModelInstance *comp);

/* Provided by each model. */
void model_set_start_values(ModelData *data);
/* Called at fmi2/fmi3ExitInitializationMode: check parameters, compute derived values, set
 * initial outputs. On a bad parameter, log one message naming the parameter and return
 * MODEL_ERROR. */
ModelStatus model_initialize(ModelInstance *comp, ModelData *data);
/* Advance from t by h, reading inputs and writing outputs in `data`. */
ModelStatus model_do_step(ModelInstance *comp, ModelData *data, double t, double h);
/* Where the variable with value reference `vr` is stored, NULL when the model has no variable of
 * that type there. Get and set are the glue's: before it touches the storage it checks the value
 * reference against the generated variable table (modelDescription.xml) and answers an unknown
 * one, setting an output or calculated value, or setting a fixed parameter after initialisation
 * with fmi2Error (fmi3Error) and a logged message that names the variable. */
double *model_real(ModelData *data, unsigned vr);
int *model_integer(ModelData *data, unsigned vr);
bool *model_boolean(ModelData *data, unsigned vr);

/* Optional: a model whose config.h defines the predicate MODEL_WATCHES_REAL(vr) provides this.
 * The glue calls it after fmi2SetReal (fmi3SetFloat64, per array element) stored, into a watched Real, a value different from the
 * previous one (NaN to NaN is no change), so the model can note, e.g., a new plan once instead
 * of rescanning its inputs every step. Other values are stored with no comparison and no call. */
void model_real_changed(ModelData *data, unsigned vr);

#endif
