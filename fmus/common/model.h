/*
 * Contract between the FMI 2.0 glue (written once, in fmus/common/) and each model
 * (fmus/<Model>/model.c + config.h). The glue owns the FMI API, the instance lifecycle and
 * state machine, logging and value-reference dispatch; a model holds only its maths.
 *
 * Each model folder provides:
 *   config.h           MODEL_IDENTIFIER, MODEL_GUID, an enum of value references, and
 *                      `struct ModelData { ... }` (parameters, inputs, outputs, state)
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
/* Called at fmi2ExitInitializationMode: check parameters, compute derived values, set
 * initial outputs. On a bad parameter, log one message naming the parameter and return
 * MODEL_ERROR. */
ModelStatus model_initialize(ModelInstance *comp, ModelData *data);
/* Advance from t by h, reading inputs and writing outputs in `data`. */
ModelStatus model_do_step(ModelInstance *comp, ModelData *data, double t, double h);
/* Get/set one scalar by value reference; return MODEL_ERROR (and log) for an unknown one.
 * Set returns MODEL_ERROR for a fixed parameter after initialisation (the glue also checks
 * causality/variability where it knows it). */
ModelStatus model_get_real(ModelInstance *comp, ModelData *data, unsigned vr, double *value);
ModelStatus model_set_real(ModelInstance *comp, ModelData *data, unsigned vr, double value);
ModelStatus model_get_integer(ModelInstance *comp, ModelData *data, unsigned vr, int *value);
ModelStatus model_set_integer(ModelInstance *comp, ModelData *data, unsigned vr, int value);
ModelStatus model_get_boolean(ModelInstance *comp, ModelData *data, unsigned vr, bool *value);
ModelStatus model_set_boolean(ModelInstance *comp, ModelData *data, unsigned vr, bool value);

#endif
