/*
 * ArtificialPotentialField FMU model: parameters, the scan inputs and the step. The field is in
 * apf.c. The parameters VFH also has (distance limits, robot radius, safety distance) keep VFH's
 * names, meanings and defaults, so a scenario swaps one for the other by changing `fmu` and the
 * method's own parameters.
 */
#include <math.h>

#include "apf.h"
#include "model_binding.h" /* generated: what the glue, compiled once for every model, needs to know of this one */

void model_set_start_values(ModelData *data) {
    data->distance_limit_min = 0.05;
    data->distance_limit_max = 2.0;
    data->robot_radius = 0.1;
    data->safety_distance = 0.1;
    data->influence_distance = 1.0;
    data->attractive_gain = 1.0;
    data->repulsive_gain = 0.005;
    data->max_target_deviation = M_PI; /* never trapped: see apf.c */
    for (int i = 0; i < APF_MAX_READINGS; i++) data->ranges[i] = data->angles[i] = NAN;
    data->target_dir = 0.0;
    data->steering_dir = 0.0;
    data->force_x = data->force_y = 0.0;
    data->nearest_distance = NAN;
    data->repelling_readings = 0;
    data->direction_status = APF_FORCE;
    data->target_dir_free = true;
    data->angles_changed = true;
}

/* Logs and fails when `ok` is false; the message names the parameter. */
static bool check(ModelInstance *comp, bool ok, const char *name, const char *rule, double value) {
    if (!ok) model_log_error(comp, "%s %s, got %g", name, rule, value);
    return ok;
}

static bool non_negative(double value) { return value >= 0.0 && isfinite(value); }
static bool positive(double value) { return value > 0.0 && isfinite(value); }

static bool parameters_valid(ModelInstance *comp, const ModelData *d) {
    return check(comp, non_negative(d->distance_limit_min), "distance_limit_min", "must be finite and >= 0",
                 d->distance_limit_min) &&
           check(comp, d->distance_limit_max > d->distance_limit_min && isfinite(d->distance_limit_max),
                 "distance_limit_max", "must be finite and > distance_limit_min", d->distance_limit_max) &&
           check(comp, non_negative(d->robot_radius), "robot_radius", "must be finite and >= 0",
                 d->robot_radius) &&
           check(comp, non_negative(d->safety_distance), "safety_distance", "must be finite and >= 0",
                 d->safety_distance) &&
           check(comp, positive(d->influence_distance), "influence_distance", "must be finite and > 0",
                 d->influence_distance) &&
           check(comp, positive(d->attractive_gain), "attractive_gain", "must be finite and > 0",
                 d->attractive_gain) &&
           check(comp, non_negative(d->repulsive_gain), "repulsive_gain", "must be finite and >= 0",
                 d->repulsive_gain) &&
           check(comp, d->max_target_deviation > 0.0 && d->max_target_deviation <= M_PI,
                 "max_target_deviation", "must be in (0, pi]", d->max_target_deviation);
}

ModelStatus model_initialize(ModelInstance *comp, ModelData *data) {
    if (!parameters_valid(comp, data)) return MODEL_ERROR;
    apf_step(data); /* initial outputs from the initial inputs; the field keeps no state */
    return MODEL_OK;
}

ModelStatus model_do_step(ModelInstance *comp, ModelData *data, double t, double h) {
    (void)comp;
    (void)t;
    (void)h;
    apf_step(data);
    return MODEL_OK;
}

static bool is_reading(unsigned vr, unsigned first) { return vr >= first && vr < first + APF_MAX_READINGS; }

double *model_real(ModelData *d, unsigned vr) {
    /* The scan first: 1440 of the 1441 values set every step. */
    if (is_reading(vr, VR_RANGES)) return &d->ranges[vr - VR_RANGES];
    if (is_reading(vr, VR_ANGLES)) return &d->angles[vr - VR_ANGLES];
    switch (vr) {
    case VR_TARGET_DIR: return &d->target_dir;
    case VR_STEERING_DIR: return &d->steering_dir;
    case VR_FORCE_X: return &d->force_x;
    case VR_FORCE_Y: return &d->force_y;
    case VR_NEAREST_DISTANCE: return &d->nearest_distance;
    case VR_DISTANCE_LIMIT_MIN: return &d->distance_limit_min;
    case VR_DISTANCE_LIMIT_MAX: return &d->distance_limit_max;
    case VR_ROBOT_RADIUS: return &d->robot_radius;
    case VR_SAFETY_DISTANCE: return &d->safety_distance;
    case VR_INFLUENCE_DISTANCE: return &d->influence_distance;
    case VR_ATTRACTIVE_GAIN: return &d->attractive_gain;
    case VR_REPULSIVE_GAIN: return &d->repulsive_gain;
    case VR_MAX_TARGET_DEVIATION: return &d->max_target_deviation;
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
    case VR_REPELLING_READINGS: return &d->repelling_readings;
    case VR_DIRECTION_STATUS: return &d->direction_status;
    default: return NULL;
    }
}

bool *model_boolean(ModelData *d, unsigned vr) { return vr == VR_TARGET_DIR_FREE ? &d->target_dir_free : NULL; }
