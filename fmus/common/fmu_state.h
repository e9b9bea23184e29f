/*
 * FMU state for both FMI versions' glue: a saved copy of an instance's model data, its time and its
 * position in the FMI state machine, and the byte form of that copy (serialised FMU state).
 *
 * A model's ModelData holds values only, no pointers (see model.h), so a copy of its bytes is a
 * complete, independent state: restoring it and stepping again gives bit-identical results. This
 * file knows no model (the glue passes the data size and GUID), so it is compiled with the glue.
 */
#ifndef NAVCOSIM_FMU_STATE_H
#define NAVCOSIM_FMU_STATE_H

#include <stdbool.h>
#include <stddef.h>

#include "model.h"

typedef struct FmuState FmuState;

/* A new, empty state for `data_size` bytes of model data (NULL when out of memory). */
FmuState *fmu_state_new(size_t data_size);
void fmu_state_free(FmuState *state);
/* Whether `state` was made by fmu_state_new for `data_size` bytes (a cheap guard against foreign
 * pointers). */
bool fmu_state_is_valid(const FmuState *state, size_t data_size);

void fmu_state_save(FmuState *state, const ModelData *data, double time, int instance_state);
void fmu_state_restore(const FmuState *state, ModelData *data, double *time, int *instance_state);

/* Bytes of a serialised state of `data_size` bytes of model data: a header naming the format, the
 * FMI version and the model's GUID, then time, instance state and the model data (native byte
 * order: the same binary reads it). */
size_t fmu_state_serialized_size(size_t data_size);
void fmu_state_serialize(const FmuState *state, int fmi_version, const char *guid, unsigned char *bytes);
/* Fill `state` from `bytes`; returns NULL, or why the bytes are not a state of this FMU (`guid`). */
const char *fmu_state_deserialize(FmuState *state, int fmi_version, const char *guid, const unsigned char *bytes,
                                  size_t size);

#endif
