/*
 * AvoidanceMixer FMU model: fuses the pure-pursuit command with the VFH steering direction
 * (thesis section 4.3.3, Figure 4.12; MathWorks' rule in shared/reference/matlab-blocks.md 1.2).
 *
 *   stopped (3): goal_reached                       -> v = omega = steering_angle = 0
 *   recover (2): steering_dir is NaN (nothing free)  -> differential drive: turn on the spot,
 *                v = 0, omega = +-recovery_angular_velocity toward the side that was last free;
 *                bicycle (cannot turn on the spot): reverse at recovery_linear_velocity with full
 *                lock away from that side, so the nose swings toward it.
 *   avoid   (1): |steering_dir - target_dir| > direction_tolerance
 *                -> omega = avoid_gain * steering_dir, v = avoid_speed_factor * v_in
 *   follow  (0): otherwise the pure-pursuit (v_in, omega_in) is kept.
 *
 * For the bicycle the command becomes a steering angle atan2(omega * wheelbase, v), folded into
 * (-pi/2, pi/2] and clipped to +-max_steering_angle (MATLAB's bicycleKinematics conversion); the
 * omega output is then the yaw rate that angle gives, v tan(steering_angle) / wheelbase. For the
 * differential drive steering_angle is 0.
 */
#include <math.h>

#include "model.h"
#include "config.h"

#ifndef M_PI /* not declared by <math.h> under -std=c99 */
#define M_PI 3.14159265358979323846
#endif

void model_set_start_values(ModelData *data) {
    data->vehicle_type = VEHICLE_DIFFERENTIAL;
    data->wheelbase = 1.0;              /* bicycleKinematics default */
    data->max_steering_angle = M_PI / 4; /* bicycleKinematics default */
    data->direction_tolerance = 0.1;    /* MathWorks' PP + VFH example */
    data->avoid_gain = 0.5;             /* MathWorks' PP + VFH example */
    data->avoid_speed_factor = 1.0;
    data->recovery_angular_velocity = 0.5;
    data->recovery_linear_velocity = 0.1;
    data->v_in = data->omega_in = data->target_dir = data->steering_dir = 0.0;
    data->goal_reached = false;
    data->v = data->omega = data->steering_angle = 0.0;
    data->mode = MODE_FOLLOW;
    data->initialized = false;
    data->recovery_sign = 1.0;
}

static double wrap_to_pi(double angle) {
    if (fabs(angle) <= M_PI) return angle;
    double shifted = fmod(angle + M_PI, 2.0 * M_PI);
    if (shifted < 0.0) shifted += 2.0 * M_PI;
    if (shifted == 0.0 && angle + M_PI > 0.0) shifted = 2.0 * M_PI;
    return shifted - M_PI;
}

/* Bicycle steering angle for (v, omega): folded into (-pi/2, pi/2], clipped to the lock. */
static double steering_angle_for(const ModelData *data, double v, double omega) {
    double angle = atan2(omega * data->wheelbase, v);
    if (angle > M_PI / 2) angle -= M_PI;
    else if (angle <= -M_PI / 2) angle += M_PI;
    if (angle > data->max_steering_angle) angle = data->max_steering_angle;
    if (angle < -data->max_steering_angle) angle = -data->max_steering_angle;
    return angle;
}

/* Evaluate the rule for the current inputs; `recovery_sign` remembers the last free side. */
static void compute_outputs(ModelData *data, double *recovery_sign) {
    const bool bicycle = data->vehicle_type == VEHICLE_BICYCLE;
    double v = data->v_in, omega = data->omega_in;
    if (!isnan(data->steering_dir) && data->steering_dir != 0.0)
        *recovery_sign = data->steering_dir > 0 ? 1.0 : -1.0;

    if (data->goal_reached) {
        data->mode = MODE_STOPPED;
        data->v = data->omega = data->steering_angle = 0.0;
        return;
    }
    if (isnan(data->steering_dir)) {
        data->mode = MODE_RECOVER;
        if (bicycle) {
            data->v = -data->recovery_linear_velocity;
            data->steering_angle = -*recovery_sign * data->max_steering_angle;
            data->omega = data->v * tan(data->steering_angle) / data->wheelbase;
        } else {
            data->v = 0.0;
            data->omega = *recovery_sign * data->recovery_angular_velocity;
            data->steering_angle = 0.0;
        }
        return;
    }
    if (fabs(wrap_to_pi(data->steering_dir - data->target_dir)) > data->direction_tolerance) {
        data->mode = MODE_AVOID;
        omega = data->avoid_gain * data->steering_dir;
        v = data->avoid_speed_factor * data->v_in;
    } else {
        data->mode = MODE_FOLLOW;
    }
    data->v = v;
    if (bicycle) {
        data->steering_angle = steering_angle_for(data, v, omega);
        data->omega = v * tan(data->steering_angle) / data->wheelbase;
    } else {
        data->omega = omega;
        data->steering_angle = 0.0;
    }
}

ModelStatus model_initialize(ModelInstance *comp, ModelData *data) {
    if (data->vehicle_type != VEHICLE_DIFFERENTIAL && data->vehicle_type != VEHICLE_BICYCLE) {
        model_log_error(comp, "vehicle_type must be 0 (differential) or 1 (bicycle), got %d",
                        data->vehicle_type);
        return MODEL_ERROR;
    }
    if (data->vehicle_type == VEHICLE_BICYCLE && !(data->wheelbase > 0.0)) {
        model_log_error(comp, "wheelbase must be > 0 for the bicycle, got %g", data->wheelbase);
        return MODEL_ERROR;
    }
    const bool lock_valid = data->max_steering_angle > 0.0 && data->max_steering_angle < M_PI / 2;
    if (data->vehicle_type == VEHICLE_BICYCLE && !lock_valid) {
        model_log_error(comp, "max_steering_angle must be in (0, pi/2) for the bicycle, got %g",
                        data->max_steering_angle);
        return MODEL_ERROR;
    }
    if (!(data->direction_tolerance >= 0.0)) {
        model_log_error(comp, "direction_tolerance must be >= 0, got %g", data->direction_tolerance);
        return MODEL_ERROR;
    }
    if (!(data->recovery_angular_velocity >= 0.0)) {
        model_log_error(comp, "recovery_angular_velocity must be >= 0, got %g",
                        data->recovery_angular_velocity);
        return MODEL_ERROR;
    }
    if (!(data->recovery_linear_velocity >= 0.0)) {
        model_log_error(comp, "recovery_linear_velocity must be >= 0, got %g",
                        data->recovery_linear_velocity);
        return MODEL_ERROR;
    }
    if (!isfinite(data->avoid_gain) || !isfinite(data->avoid_speed_factor)) {
        model_log_error(comp, "avoid_gain and avoid_speed_factor must be finite, got %g and %g",
                        data->avoid_gain, data->avoid_speed_factor);
        return MODEL_ERROR;
    }
    data->initialized = true;
    double recovery_sign = data->recovery_sign;
    compute_outputs(data, &recovery_sign);
    return MODEL_OK;
}

ModelStatus model_do_step(ModelInstance *comp, ModelData *data, double t, double h) {
    (void)comp;
    (void)t;
    (void)h;
    compute_outputs(data, &data->recovery_sign);
    return MODEL_OK;
}

static double *real_variable(ModelData *d, unsigned vr, const char **parameter) {
    *parameter = NULL;
    switch (vr) {
    case VR_WHEELBASE: *parameter = "wheelbase"; return &d->wheelbase;
    case VR_MAX_STEERING_ANGLE: *parameter = "max_steering_angle"; return &d->max_steering_angle;
    case VR_DIRECTION_TOLERANCE: *parameter = "direction_tolerance"; return &d->direction_tolerance;
    case VR_AVOID_GAIN: *parameter = "avoid_gain"; return &d->avoid_gain;
    case VR_AVOID_SPEED_FACTOR: *parameter = "avoid_speed_factor"; return &d->avoid_speed_factor;
    case VR_RECOVERY_ANGULAR_VELOCITY:
        *parameter = "recovery_angular_velocity";
        return &d->recovery_angular_velocity;
    case VR_RECOVERY_LINEAR_VELOCITY:
        *parameter = "recovery_linear_velocity";
        return &d->recovery_linear_velocity;
    case VR_V_IN: return &d->v_in;
    case VR_OMEGA_IN: return &d->omega_in;
    case VR_TARGET_DIR: return &d->target_dir;
    case VR_STEERING_DIR: return &d->steering_dir;
    case VR_V: return &d->v;
    case VR_OMEGA: return &d->omega;
    case VR_STEERING_ANGLE: return &d->steering_angle;
    default: return NULL;
    }
}

ModelStatus model_get_real(ModelInstance *comp, ModelData *data, unsigned vr, double *value) {
    const char *parameter;
    double *variable = real_variable(data, vr, &parameter);
    if (!variable) {
        model_log_error(comp, "unknown Real value reference %u", vr);
        return MODEL_ERROR;
    }
    *value = *variable;
    return MODEL_OK;
}

ModelStatus model_set_real(ModelInstance *comp, ModelData *data, unsigned vr, double value) {
    const char *parameter;
    double *variable = real_variable(data, vr, &parameter);
    if (!variable || vr >= VR_V) {
        model_log_error(comp, "Real value reference %u is unknown or not settable", vr);
        return MODEL_ERROR;
    }
    if (parameter && data->initialized) {
        model_log_error(comp, "parameter %s is fixed after initialisation", parameter);
        return MODEL_ERROR;
    }
    *variable = value;
    return MODEL_OK;
}

ModelStatus model_get_integer(ModelInstance *comp, ModelData *data, unsigned vr, int *value) {
    switch (vr) {
    case VR_VEHICLE_TYPE: *value = data->vehicle_type; return MODEL_OK;
    case VR_MODE: *value = data->mode; return MODEL_OK;
    default: model_log_error(comp, "unknown Integer value reference %u", vr); return MODEL_ERROR;
    }
}

ModelStatus model_set_integer(ModelInstance *comp, ModelData *data, unsigned vr, int value) {
    if (vr != VR_VEHICLE_TYPE) {
        model_log_error(comp, "Integer value reference %u is unknown or not settable", vr);
        return MODEL_ERROR;
    }
    if (data->initialized) {
        model_log_error(comp, "parameter vehicle_type is fixed after initialisation");
        return MODEL_ERROR;
    }
    data->vehicle_type = value;
    return MODEL_OK;
}

ModelStatus model_get_boolean(ModelInstance *comp, ModelData *data, unsigned vr, bool *value) {
    if (vr == VR_GOAL_REACHED) {
        *value = data->goal_reached;
        return MODEL_OK;
    }
    model_log_error(comp, "unknown Boolean value reference %u", vr);
    return MODEL_ERROR;
}

ModelStatus model_set_boolean(ModelInstance *comp, ModelData *data, unsigned vr, bool value) {
    if (vr == VR_GOAL_REACHED) {
        data->goal_reached = value;
        return MODEL_OK;
    }
    model_log_error(comp, "Boolean value reference %u is unknown or not settable", vr);
    return MODEL_ERROR;
}
