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
    size_t size; /* bytes of `data`: sizeof(ModelData) */
    unsigned char data[];
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

FmuState *fmu_state_new(size_t data_size) {
    FmuState *state = calloc(1, sizeof *state + data_size);
    if (state != NULL) {
        state->tag = STATE_TAG;
        state->size = data_size;
    }
    return state;
}

void fmu_state_free(FmuState *state) {
    if (state != NULL) {
        state->tag = 0;
        free(state);
    }
}

bool fmu_state_is_valid(const FmuState *state, size_t data_size) {
    return state != NULL && state->tag == STATE_TAG && state->size == data_size;
}

void fmu_state_save(FmuState *state, const ModelData *data, double time, int instance_state) {
    memcpy(state->data, data, state->size);
    state->time = time;
    state->instance_state = instance_state;
}

void fmu_state_restore(const FmuState *state, ModelData *data, double *time, int *instance_state) {
    memcpy(data, state->data, state->size);
    *time = state->time;
    *instance_state = state->instance_state;
}

size_t fmu_state_serialized_size(size_t data_size) { return sizeof(Header) + data_size; }

static void make_header(Header *header, int fmi_version, const char *guid, size_t data_size) {
    memset(header, 0, sizeof *header);
    strncpy(header->magic, MAGIC, MAGIC_SIZE - 1);
    strncpy(header->guid, guid, GUID_SIZE - 1);
    header->fmi_version = (uint32_t)fmi_version;
    header->data_size = (uint32_t)data_size;
}

void fmu_state_serialize(const FmuState *state, int fmi_version, const char *guid, unsigned char *bytes) {
    Header header;
    make_header(&header, fmi_version, guid, state->size);
    header.time = state->time;
    header.instance_state = state->instance_state;
    memcpy(bytes, &header, sizeof header);
    memcpy(bytes + sizeof header, state->data, state->size);
}

const char *fmu_state_deserialize(FmuState *state, int fmi_version, const char *guid, const unsigned char *bytes,
                                  size_t size) {
    Header expected, found;
    if (size != fmu_state_serialized_size(state->size)) {
        return "the serialized state has the wrong size for this FMU";
    }
    make_header(&expected, fmi_version, guid, state->size);
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
    memcpy(state->data, bytes + sizeof found, state->size);
    return NULL;
}
