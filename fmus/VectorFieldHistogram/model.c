/*
 * VectorFieldHistogram FMU model: parameters, the scan inputs and the step. The algorithm is in
 * vfh.c. Parameter defaults are MATLAB's controllerVFH defaults.
 */
#include <math.h>
#include <string.h>

#include "vfh.h"
#include "model_binding.h" /* generated: what the glue, compiled once for every model, needs to know of this one */

void model_set_start_values(ModelData *data) {
    data->num_angular_sectors = 180;
    data->distance_limit_min = 0.05;
    data->distance_limit_max = 2.0;
    data->robot_radius = 0.1;
    data->safety_distance = 0.1;
    data->min_turning_radius = 0.1;
    data->target_direction_weight = 5.0;
    data->current_direction_weight = 2.0;
    data->previous_direction_weight = 2.0;
    data->histogram_threshold_low = 3.0;
    data->histogram_threshold_high = 10.0;
    data->narrow_opening_threshold = 0.8;
    for (int i = 0; i < VFH_MAX_READINGS; i++) data->ranges[i] = data->angles[i] = NAN;
    data->target_dir = 0.0;
    data->steering_dir = 0.0;
    data->free_sectors = data->num_valleys = 0;
    data->target_dir_free = false;
    memset(data->binary_histogram, 0, sizeof data->binary_histogram);
    data->previous_direction = 0.0;
    data->angles_changed = true;
    data->histograms_built = false;
}

/* Logs and fails when `ok` is false; the message names the parameter. */
static bool check(ModelInstance *comp, bool ok, const char *name, const char *rule, double value) {
    if (!ok) model_log_error(comp, "%s %s, got %g", name, rule, value);
    return ok;
}

static bool parameters_valid(ModelInstance *comp, const ModelData *d) {
    return check(comp, d->num_angular_sectors >= 1 && d->num_angular_sectors <= VFH_MAX_SECTORS,
                 "num_angular_sectors", "must be in 1..720 (compiled capacity)", d->num_angular_sectors) &&
           check(comp, d->distance_limit_min >= 0.0, "distance_limit_min", "must be >= 0",
                 d->distance_limit_min) &&
           check(comp, d->distance_limit_max > d->distance_limit_min && isfinite(d->distance_limit_max),
                 "distance_limit_max", "must be finite and > distance_limit_min", d->distance_limit_max) &&
           check(comp, d->robot_radius >= 0.0, "robot_radius", "must be >= 0", d->robot_radius) &&
           check(comp, d->safety_distance >= 0.0, "safety_distance", "must be >= 0", d->safety_distance) &&
           check(comp, d->min_turning_radius >= 0.0, "min_turning_radius", "must be >= 0",
                 d->min_turning_radius) &&
           check(comp, d->target_direction_weight >= 0.0, "target_direction_weight", "must be >= 0",
                 d->target_direction_weight) &&
           check(comp, d->current_direction_weight >= 0.0, "current_direction_weight", "must be >= 0",
                 d->current_direction_weight) &&
           check(comp, d->previous_direction_weight >= 0.0, "previous_direction_weight", "must be >= 0",
                 d->previous_direction_weight) &&
           check(comp, d->histogram_threshold_low >= 0.0, "histogram_threshold_low", "must be >= 0",
                 d->histogram_threshold_low) &&
           check(comp, d->histogram_threshold_high >= d->histogram_threshold_low, "histogram_threshold_high",
                 "must be >= histogram_threshold_low", d->histogram_threshold_high) &&
           check(comp, d->narrow_opening_threshold > 0.0, "narrow_opening_threshold", "must be > 0",
                 d->narrow_opening_threshold);
}

ModelStatus model_initialize(ModelInstance *comp, ModelData *data) {
    if (!parameters_valid(comp, data)) return MODEL_ERROR;
    vfh_prepare_sectors(data);
    /* Initial outputs from the initial inputs, without touching the histogram memory, so the first
     * doStep is MATLAB's first call. */
    bool binary_histogram[VFH_MAX_SECTORS];
    memcpy(binary_histogram, data->binary_histogram, sizeof binary_histogram);
    double previous_direction = data->previous_direction;
    vfh_step(data);
    memcpy(data->binary_histogram, binary_histogram, sizeof binary_histogram);
    data->previous_direction = previous_direction;
    data->histograms_built = false; /* built on the histogram memory just put back */
    return MODEL_OK;
}

ModelStatus model_do_step(ModelInstance *comp, ModelData *data, double t, double h) {
    (void)comp;
    (void)t;
    (void)h;
    vfh_step(data);
    return MODEL_OK;
}

static bool is_reading(unsigned vr, unsigned first) { return vr >= first && vr < first + VFH_MAX_READINGS; }

double *model_real(ModelData *d, unsigned vr) {
    /* The scan first: 1440 of the 1441 values set every step. */
    if (is_reading(vr, VR_RANGES)) return &d->ranges[vr - VR_RANGES];
    if (is_reading(vr, VR_ANGLES)) return &d->angles[vr - VR_ANGLES];
    switch (vr) {
    case VR_TARGET_DIR: return &d->target_dir;
    case VR_STEERING_DIR: return &d->steering_dir;
    case VR_DISTANCE_LIMIT_MIN: return &d->distance_limit_min;
    case VR_DISTANCE_LIMIT_MAX: return &d->distance_limit_max;
    case VR_ROBOT_RADIUS: return &d->robot_radius;
    case VR_SAFETY_DISTANCE: return &d->safety_distance;
    case VR_MIN_TURNING_RADIUS: return &d->min_turning_radius;
    case VR_TARGET_DIRECTION_WEIGHT: return &d->target_direction_weight;
    case VR_CURRENT_DIRECTION_WEIGHT: return &d->current_direction_weight;
    case VR_PREVIOUS_DIRECTION_WEIGHT: return &d->previous_direction_weight;
    case VR_HISTOGRAM_THRESHOLD_LOW: return &d->histogram_threshold_low;
    case VR_HISTOGRAM_THRESHOLD_HIGH: return &d->histogram_threshold_high;
    case VR_NARROW_OPENING_THRESHOLD: return &d->narrow_opening_threshold;
    default: return NULL;
    }
}

/* Called for a reading angle that changed value: the cached cosines and sines are stale. */
void model_real_changed(ModelData *data, unsigned vr) {
    (void)vr;
    data->angles_changed = true;
}

int *model_integer(ModelData *d, unsigned vr) {
    switch (vr) {
    case VR_NUM_ANGULAR_SECTORS: return &d->num_angular_sectors;
    case VR_FREE_SECTORS: return &d->free_sectors;
    case VR_NUM_VALLEYS: return &d->num_valleys;
    default: return NULL;
    }
}

bool *model_boolean(ModelData *d, unsigned vr) { return vr == VR_TARGET_DIR_FREE ? &d->target_dir_free : NULL; }
