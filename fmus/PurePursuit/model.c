/*
 * PurePursuit FMU model: parameters, the waypoint input and the step. The geometry is in
 * pure_pursuit.c.
 *
 * Differences from MATLAB's block, on purpose: at the goal (distance to the last waypoint within
 * goal_tolerance) v = omega = 0, so the vehicle stops (MATLAB keeps driving at
 * DesiredLinearVelocity and leaves the stop to the caller); angular_velocity_law = 1 gives the
 * nav2 form omega = v * kappa. A change of any waypoint element (a replanned path, or rows
 * appearing or turning NaN: a new waypoint count) restarts the projection search over every
 * segment from waypoint 1, as MATLAB does when its Waypoints property changes, so the new path is
 * followed from the vehicle's current pose; resending the same values is no change. goal_reached
 * is evaluated every step, not latched: a new plan after the goal drives again.
 */
#include <math.h>

#include "angles.h"
#include "model.h"
#include "pure_pursuit.h"
#include "model_binding.h" /* generated: what the glue, compiled once for every model, needs to know of this one */

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
    double alpha = wrap_to_pi(atan2(data->lookahead_y - data->y, data->lookahead_x - data->x) -
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

double *model_real(ModelData *data, unsigned vr) {
    if (is_waypoint(vr, VR_WAYPOINTS_X)) return &data->waypoints_x[vr - VR_WAYPOINTS_X];
    if (is_waypoint(vr, VR_WAYPOINTS_Y)) return &data->waypoints_y[vr - VR_WAYPOINTS_Y];
    switch (vr) {
    case VR_DESIRED_LINEAR_VELOCITY: return &data->desired_linear_velocity;
    case VR_MAX_ANGULAR_VELOCITY: return &data->max_angular_velocity;
    case VR_LOOKAHEAD_DISTANCE: return &data->lookahead_distance;
    case VR_GOAL_TOLERANCE: return &data->goal_tolerance;
    case VR_X: return &data->x;
    case VR_Y: return &data->y;
    case VR_THETA: return &data->theta;
    case VR_V: return &data->v;
    case VR_OMEGA: return &data->omega;
    case VR_TARGET_DIR: return &data->target_dir;
    case VR_LOOKAHEAD_X: return &data->lookahead_x;
    case VR_LOOKAHEAD_Y: return &data->lookahead_y;
    case VR_GOAL_DISTANCE: return &data->goal_distance;
    default: return NULL;
    }
}

/* Called for a waypoint element that changed value: a new plan, compacted once by the next step. */
void model_real_changed(ModelData *data, unsigned vr) {
    (void)vr;
    data->waypoints_changed = true;
}

int *model_integer(ModelData *data, unsigned vr) {
    return vr == VR_ANGULAR_VELOCITY_LAW ? &data->angular_velocity_law : NULL;
}

bool *model_boolean(ModelData *data, unsigned vr) { return vr == VR_GOAL_REACHED ? &data->goal_reached : NULL; }
