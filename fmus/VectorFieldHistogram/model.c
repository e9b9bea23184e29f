/*
 * VectorFieldHistogram FMU model: parameters, the scan inputs and the step. The algorithm is in
 * vfh.c. Parameter defaults are MATLAB's controllerVFH defaults.
 */
#include <math.h>
#include <string.h>

#include "vfh.h"

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
    data->initialized = false;
    memset(data->binary_histogram, 0, sizeof data->binary_histogram);
    data->previous_direction = 0.0;
    data->angles_changed = true;
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
    data->initialized = true;
    vfh_prepare_sectors(data);
    /* Initial outputs from the initial inputs, without touching the histogram memory, so the first
     * doStep is MATLAB's first call. */
    bool binary_histogram[VFH_MAX_SECTORS];
    memcpy(binary_histogram, data->binary_histogram, sizeof binary_histogram);
    double previous_direction = data->previous_direction;
    vfh_step(data);
    memcpy(data->binary_histogram, binary_histogram, sizeof binary_histogram);
    data->previous_direction = previous_direction;
    return MODEL_OK;
}

ModelStatus model_do_step(ModelInstance *comp, ModelData *data, double t, double h) {
    (void)comp;
    (void)t;
    (void)h;
    vfh_step(data);
    return MODEL_OK;
}

/* The Real parameters in value-reference order, with their names for messages. */
static double *real_parameter(ModelData *d, unsigned vr, const char **name) {
    switch (vr) {
    case VR_DISTANCE_LIMIT_MIN: *name = "distance_limit_min"; return &d->distance_limit_min;
    case VR_DISTANCE_LIMIT_MAX: *name = "distance_limit_max"; return &d->distance_limit_max;
    case VR_ROBOT_RADIUS: *name = "robot_radius"; return &d->robot_radius;
    case VR_SAFETY_DISTANCE: *name = "safety_distance"; return &d->safety_distance;
    case VR_MIN_TURNING_RADIUS: *name = "min_turning_radius"; return &d->min_turning_radius;
    case VR_TARGET_DIRECTION_WEIGHT: *name = "target_direction_weight"; return &d->target_direction_weight;
    case VR_CURRENT_DIRECTION_WEIGHT: *name = "current_direction_weight"; return &d->current_direction_weight;
    case VR_PREVIOUS_DIRECTION_WEIGHT:
        *name = "previous_direction_weight";
        return &d->previous_direction_weight;
    case VR_HISTOGRAM_THRESHOLD_LOW: *name = "histogram_threshold_low"; return &d->histogram_threshold_low;
    case VR_HISTOGRAM_THRESHOLD_HIGH: *name = "histogram_threshold_high"; return &d->histogram_threshold_high;
    case VR_NARROW_OPENING_THRESHOLD: *name = "narrow_opening_threshold"; return &d->narrow_opening_threshold;
    default: return NULL;
    }
}

static bool is_reading(unsigned vr, unsigned first) { return vr >= first && vr < first + VFH_MAX_READINGS; }

ModelStatus model_get_real(ModelInstance *comp, ModelData *data, unsigned vr, double *value) {
    const char *name;
    double *parameter = real_parameter(data, vr, &name);
    if (parameter) *value = *parameter;
    else if (is_reading(vr, VR_RANGES)) *value = data->ranges[vr - VR_RANGES];
    else if (is_reading(vr, VR_ANGLES)) *value = data->angles[vr - VR_ANGLES];
    else if (vr == VR_TARGET_DIR) *value = data->target_dir;
    else if (vr == VR_STEERING_DIR) *value = data->steering_dir;
    else {
        model_log_error(comp, "unknown Real value reference %u", vr);
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

ModelStatus model_set_real(ModelInstance *comp, ModelData *data, unsigned vr, double value) {
    /* The scan first: 1440 of the 1441 values set every step. */
    if (is_reading(vr, VR_RANGES)) {
        data->ranges[vr - VR_RANGES] = value;
        return MODEL_OK;
    }
    if (is_reading(vr, VR_ANGLES)) {
        double *angle = &data->angles[vr - VR_ANGLES];
        if (!(*angle == value || (isnan(*angle) && isnan(value)))) data->angles_changed = true;
        *angle = value;
        return MODEL_OK;
    }
    if (vr == VR_TARGET_DIR) {
        data->target_dir = value;
        return MODEL_OK;
    }
    const char *name;
    double *parameter = real_parameter(data, vr, &name);
    if (!parameter) {
        model_log_error(comp, "Real value reference %u is unknown or not settable", vr);
        return MODEL_ERROR;
    }
    if (data->initialized) {
        model_log_error(comp, "parameter %s is fixed after initialisation", name);
        return MODEL_ERROR;
    }
    *parameter = value;
    return MODEL_OK;
}

ModelStatus model_get_integer(ModelInstance *comp, ModelData *data, unsigned vr, int *value) {
    switch (vr) {
    case VR_NUM_ANGULAR_SECTORS: *value = data->num_angular_sectors; return MODEL_OK;
    case VR_FREE_SECTORS: *value = data->free_sectors; return MODEL_OK;
    case VR_NUM_VALLEYS: *value = data->num_valleys; return MODEL_OK;
    default: model_log_error(comp, "unknown Integer value reference %u", vr); return MODEL_ERROR;
    }
}

ModelStatus model_set_integer(ModelInstance *comp, ModelData *data, unsigned vr, int value) {
    if (vr != VR_NUM_ANGULAR_SECTORS) {
        model_log_error(comp, "Integer value reference %u is unknown or not settable", vr);
        return MODEL_ERROR;
    }
    if (data->initialized) {
        model_log_error(comp, "parameter num_angular_sectors is fixed after initialisation");
        return MODEL_ERROR;
    }
    data->num_angular_sectors = value;
    return MODEL_OK;
}

ModelStatus model_get_boolean(ModelInstance *comp, ModelData *data, unsigned vr, bool *value) {
    if (vr == VR_TARGET_DIR_FREE) {
        *value = data->target_dir_free;
        return MODEL_OK;
    }
    model_log_error(comp, "unknown Boolean value reference %u", vr);
    return MODEL_ERROR;
}

ModelStatus model_set_boolean(ModelInstance *comp, ModelData *data, unsigned vr, bool value) {
    (void)data;
    (void)value;
    model_log_error(comp, "Boolean value reference %u is unknown or not settable", vr);
    return MODEL_ERROR;
}
