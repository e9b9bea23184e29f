/*
 * What the FMI 2.0 glue (fmi2_glue.c) knows of the model it is linked with: the one object
 * `fmi2_model`, defined by the generated `model_binding.h` that each model's model.c includes. The
 * glue (and fmu_state.c) hold nothing of a model, so they are compiled once for every FMU and
 * linked into each one.
 */
#ifndef NAVCOSIM_FMI2_MODEL_H
#define NAVCOSIM_FMI2_MODEL_H

#include <stddef.h>

#include "model.h"

/* When a variable may be set; the generated table holds one of these per value reference. */
enum VariableAccess {
    ACCESS_UNKNOWN = 0,   /* no variable of this type has this value reference */
    ACCESS_READ_ONLY = 1, /* output, local, calculated parameter, constant */
    ACCESS_FIXED = 2,     /* fixed parameter: settable until initialisation ends */
    ACCESS_ANY_TIME = 3,  /* input or tunable parameter */
};

/* One FMI type's part of the generated variable table. */
typedef struct {
    const char *type_name;
    const unsigned char *access; /* enum VariableAccess per value reference */
    const char *const *names;    /* variable name per value reference, NULL where none */
    size_t size;
} VariableTable;

typedef struct {
    const char *identifier; /* MODEL_IDENTIFIER */
    const char *guid;       /* MODEL_GUID */
    size_t data_size;       /* sizeof(ModelData) */
    VariableTable real, integer, boolean;
    /* With a model whose config.h defines MODEL_WATCHES_REAL(vr): that predicate per Real value
     * reference (real.size entries) and model_real_changed; both NULL otherwise. */
    const unsigned char *real_watched;
    void (*real_changed)(ModelData *data, unsigned vr);
} Fmi2Model;

extern const Fmi2Model fmi2_model;

#endif
