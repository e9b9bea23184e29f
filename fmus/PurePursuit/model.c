/*
 * PurePursuit FMU model: parameters, the waypoint input and the step. The geometry is in
 * pure_pursuit.c.
 *
 * Differences from MATLAB's block, on purpose: at the goal (distance to the last waypoint within
 * goal_tolerance) v = omega = 0, so the vehicle stops (MATLAB keeps driving at
 * DesiredLinearVelocity and leaves the stop to the caller); angular_velocity_law = 1 gives the
 * nav2 form omega = v * kappa. A change of any waypoint element restarts the projection search
 * from waypoint 1, as MATLAB does when its Waypoints property changes.
 */
#include <math.h>

#include "model.h"
#include "pure_pursuit.h"

void model_set_start_values(ModelData *data) {
    /* MATLAB's defaults (controllerPurePursuit); goal_tolerance has no MATLAB counterpart. */
    data->desired_linear_velocity = 0.1;
    data->max_angular_velocity = 1.0;
    data->lookahead_distance = 1.0;
    data->goal_tolerance = 0.1;
    data->angular_velocity_law = 0;
    data->x = data->y = data->theta = 0.0;
    for (int k = 0; k < PP_MAX_WAYPOINTS; k++) data->waypoints_x[k] = data->waypoints_y[k] = NAN;
    data->v = data->omega = data->target_dir = 0.0;
    data->lookahead_x = data->lookahead_y = 0.0;
    data->goal_distance = NAN;
    data->goal_reached = false;
    data->initialized = false;
    data->waypoints_changed = true;
    data->path_count = 0;
    data->projection.valid = false;
}

/* One controller evaluation from the current inputs; `projection` is updated. */
static void compute_outputs(ModelData *data, ProjectionState *projection) {
    if (data->waypoints_changed) {
        pure_pursuit_compact_path(data);
        projection->valid = false;
        data->waypoints_changed = false;
    }
    if (data->path_count == 0) {
        data->v = data->omega = data->target_dir = 0.0;
        data->lookahead_x = data->x;
        data->lookahead_y = data->y;
        data->goal_distance = NAN;
        data->goal_reached = false;
        return;
    }
    pure_pursuit_lookahead(data, projection, &data->lookahead_x, &data->lookahead_y);
    double alpha = pure_pursuit_wrap_to_pi(atan2(data->lookahead_y - data->y, data->lookahead_x - data->x) -
                                           data->theta);
    data->omega = pure_pursuit_angular_velocity(data, alpha);
    data->v = data->desired_linear_velocity;
    data->target_dir = isnan(alpha) ? 0.0 : alpha;

    int last = data->path_count - 1;
    data->goal_distance = hypot(data->path_x[last] - data->x, data->path_y[last] - data->y);
    data->goal_reached = data->goal_distance <= data->goal_tolerance;
    if (data->goal_reached) data->v = data->omega = 0.0;
}

ModelStatus model_initialize(ModelInstance *comp, ModelData *data) {
    if (!(data->lookahead_distance > 0.0) || isinf(data->lookahead_distance)) {
        model_log_error(comp, "lookahead_distance must be positive and finite, got %g",
                        data->lookahead_distance);
        return MODEL_ERROR;
    }
    if (!(data->max_angular_velocity >= 0.0)) {
        model_log_error(comp, "max_angular_velocity must be >= 0, got %g", data->max_angular_velocity);
        return MODEL_ERROR;
    }
    if (!(data->goal_tolerance >= 0.0)) {
        model_log_error(comp, "goal_tolerance must be >= 0, got %g", data->goal_tolerance);
        return MODEL_ERROR;
    }
    if (!isfinite(data->desired_linear_velocity)) {
        model_log_error(comp, "desired_linear_velocity must be finite, got %g",
                        data->desired_linear_velocity);
        return MODEL_ERROR;
    }
    if (data->angular_velocity_law != 0 && data->angular_velocity_law != 1) {
        model_log_error(comp, "angular_velocity_law must be 0 (MATLAB) or 1 (nav2 v*kappa), got %d",
                        data->angular_velocity_law);
        return MODEL_ERROR;
    }
    data->initialized = true;
    /* Initial outputs from the initial inputs; the projection state is left untouched so the first
     * doStep is MATLAB's first call. */
    ProjectionState scratch = data->projection;
    compute_outputs(data, &scratch);
    data->waypoints_changed = true;
    return MODEL_OK;
}

ModelStatus model_do_step(ModelInstance *comp, ModelData *data, double t, double h) {
    (void)comp;
    (void)t;
    (void)h;
    compute_outputs(data, &data->projection);
    return MODEL_OK;
}

static bool is_waypoint(unsigned vr, unsigned first) { return vr >= first && vr < first + PP_MAX_WAYPOINTS; }

ModelStatus model_get_real(ModelInstance *comp, ModelData *data, unsigned vr, double *value) {
    if (is_waypoint(vr, VR_WAYPOINTS_X)) { *value = data->waypoints_x[vr - VR_WAYPOINTS_X]; return MODEL_OK; }
    if (is_waypoint(vr, VR_WAYPOINTS_Y)) { *value = data->waypoints_y[vr - VR_WAYPOINTS_Y]; return MODEL_OK; }
    switch (vr) {
    case VR_DESIRED_LINEAR_VELOCITY: *value = data->desired_linear_velocity; return MODEL_OK;
    case VR_MAX_ANGULAR_VELOCITY: *value = data->max_angular_velocity; return MODEL_OK;
    case VR_LOOKAHEAD_DISTANCE: *value = data->lookahead_distance; return MODEL_OK;
    case VR_GOAL_TOLERANCE: *value = data->goal_tolerance; return MODEL_OK;
    case VR_X: *value = data->x; return MODEL_OK;
    case VR_Y: *value = data->y; return MODEL_OK;
    case VR_THETA: *value = data->theta; return MODEL_OK;
    case VR_V: *value = data->v; return MODEL_OK;
    case VR_OMEGA: *value = data->omega; return MODEL_OK;
    case VR_TARGET_DIR: *value = data->target_dir; return MODEL_OK;
    case VR_LOOKAHEAD_X: *value = data->lookahead_x; return MODEL_OK;
    case VR_LOOKAHEAD_Y: *value = data->lookahead_y; return MODEL_OK;
    case VR_GOAL_DISTANCE: *value = data->goal_distance; return MODEL_OK;
    default: model_log_error(comp, "unknown Real value reference %u", vr); return MODEL_ERROR;
    }
}

/* A waypoint element that changes value (NaN to NaN is no change) marks a new plan. */
static void set_waypoint(ModelData *data, double *element, double value) {
    bool same = (*element == value) || (isnan(*element) && isnan(value));
    if (!same) data->waypoints_changed = true;
    *element = value;
}

static ModelStatus set_parameter(ModelInstance *comp, const ModelData *data, const char *name, double *target,
                                 double value) {
    if (data->initialized) {
        model_log_error(comp, "parameter %s is fixed after initialisation", name);
        return MODEL_ERROR;
    }
    *target = value;
    return MODEL_OK;
}

ModelStatus model_set_real(ModelInstance *comp, ModelData *data, unsigned vr, double value) {
    if (is_waypoint(vr, VR_WAYPOINTS_X)) {
        set_waypoint(data, &data->waypoints_x[vr - VR_WAYPOINTS_X], value);
        return MODEL_OK;
    }
    if (is_waypoint(vr, VR_WAYPOINTS_Y)) {
        set_waypoint(data, &data->waypoints_y[vr - VR_WAYPOINTS_Y], value);
        return MODEL_OK;
    }
    switch (vr) {
    case VR_DESIRED_LINEAR_VELOCITY:
        return set_parameter(comp, data, "desired_linear_velocity", &data->desired_linear_velocity, value);
    case VR_MAX_ANGULAR_VELOCITY:
        return set_parameter(comp, data, "max_angular_velocity", &data->max_angular_velocity, value);
    case VR_LOOKAHEAD_DISTANCE:
        return set_parameter(comp, data, "lookahead_distance", &data->lookahead_distance, value);
    case VR_GOAL_TOLERANCE: return set_parameter(comp, data, "goal_tolerance", &data->goal_tolerance, value);
    case VR_X: data->x = value; return MODEL_OK;
    case VR_Y: data->y = value; return MODEL_OK;
    case VR_THETA: data->theta = value; return MODEL_OK;
    default:
        model_log_error(comp, "Real value reference %u is unknown or not settable", vr);
        return MODEL_ERROR;
    }
}

ModelStatus model_get_integer(ModelInstance *comp, ModelData *data, unsigned vr, int *value) {
    if (vr == VR_ANGULAR_VELOCITY_LAW) { *value = data->angular_velocity_law; return MODEL_OK; }
    model_log_error(comp, "unknown Integer value reference %u", vr);
    return MODEL_ERROR;
}

ModelStatus model_set_integer(ModelInstance *comp, ModelData *data, unsigned vr, int value) {
    if (vr != VR_ANGULAR_VELOCITY_LAW) {
        model_log_error(comp, "Integer value reference %u is unknown or not settable", vr);
        return MODEL_ERROR;
    }
    if (data->initialized) {
        model_log_error(comp, "parameter angular_velocity_law is fixed after initialisation");
        return MODEL_ERROR;
    }
    data->angular_velocity_law = value;
    return MODEL_OK;
}

ModelStatus model_get_boolean(ModelInstance *comp, ModelData *data, unsigned vr, bool *value) {
    if (vr == VR_GOAL_REACHED) { *value = data->goal_reached; return MODEL_OK; }
    model_log_error(comp, "unknown Boolean value reference %u", vr);
    return MODEL_ERROR;
}

ModelStatus model_set_boolean(ModelInstance *comp, ModelData *data, unsigned vr, bool value) {
    (void)data;
    (void)value;
    model_log_error(comp, "Boolean value reference %u is unknown or not settable", vr);
    return MODEL_ERROR;
}
