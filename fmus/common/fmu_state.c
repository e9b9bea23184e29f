/* FMU state save, restore and serialisation shared by the FMI 2.0 and 3.0 glue (see fmu_state.h). */
#include "fmu_state.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Marks a live FmuState; cleared on free so a freed or foreign pointer is refused. */
#define STATE_TAG 0x6e617673u /* "navs" */

struct FmuState {
    uint32_t tag;
    int instance_state;
    double time; /* [s] */
    ModelData data;
};

/* Serialised layout: magic, FMI version, GUID, payload sizes, then the payload. */
#define MAGIC "navcosim FMU state v1"
enum { MAGIC_SIZE = 24, GUID_SIZE = 64 };
typedef struct {
    char magic[MAGIC_SIZE];
    uint32_t fmi_version;
    uint32_t data_size; /* sizeof(ModelData) of the binary that wrote it */
    char guid[GUID_SIZE];
    double time;
    int32_t instance_state;
    uint32_t reserved;
} Header;

FmuState *fmu_state_new(void) {
    FmuState *state = calloc(1, sizeof *state);
    if (state != NULL) {
        state->tag = STATE_TAG;
    }
    return state;
}

void fmu_state_free(FmuState *state) {
    if (state != NULL) {
        state->tag = 0;
        free(state);
    }
}

bool fmu_state_is_valid(const FmuState *state) { return state != NULL && state->tag == STATE_TAG; }

void fmu_state_save(FmuState *state, const ModelData *data, double time, int instance_state) {
    memcpy(&state->data, data, sizeof state->data);
    state->time = time;
    state->instance_state = instance_state;
}

void fmu_state_restore(const FmuState *state, ModelData *data, double *time, int *instance_state) {
    memcpy(data, &state->data, sizeof *data);
    *time = state->time;
    *instance_state = state->instance_state;
}

size_t fmu_state_serialized_size(void) { return sizeof(Header) + sizeof(ModelData); }

static void make_header(Header *header, int fmi_version) {
    memset(header, 0, sizeof *header);
    strncpy(header->magic, MAGIC, MAGIC_SIZE - 1);
    strncpy(header->guid, MODEL_GUID, GUID_SIZE - 1);
    header->fmi_version = (uint32_t)fmi_version;
    header->data_size = (uint32_t)sizeof(ModelData);
}

void fmu_state_serialize(const FmuState *state, int fmi_version, unsigned char *bytes) {
    Header header;
    make_header(&header, fmi_version);
    header.time = state->time;
    header.instance_state = state->instance_state;
    memcpy(bytes, &header, sizeof header);
    memcpy(bytes + sizeof header, &state->data, sizeof state->data);
}

const char *fmu_state_deserialize(FmuState *state, int fmi_version, const unsigned char *bytes, size_t size) {
    Header expected, found;
    if (size != fmu_state_serialized_size()) {
        return "the serialized state has the wrong size for this FMU";
    }
    make_header(&expected, fmi_version);
    memcpy(&found, bytes, sizeof found);
    if (memcmp(found.magic, expected.magic, MAGIC_SIZE) != 0) {
        return "the bytes are not a serialized navcosim FMU state";
    }
    if (found.fmi_version != expected.fmi_version) {
        return "the serialized state was written by the other FMI version of this model";
    }
    if (memcmp(found.guid, expected.guid, GUID_SIZE) != 0 || found.data_size != expected.data_size) {
        return "the serialized state was written by another model or build (GUID or data size differ)";
    }
    state->tag = STATE_TAG;
    state->time = found.time;
    state->instance_state = found.instance_state;
    memcpy(&state->data, bytes + sizeof found, sizeof state->data);
    return NULL;
}
