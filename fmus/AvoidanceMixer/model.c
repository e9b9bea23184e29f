/*
 * AvoidanceMixer FMU model: fuses the pure-pursuit command with the VFH steering direction
 * (thesis section 4.3.3, Figure 4.12; the steering rule of MathWorks' VFH examples).
 *
 *   stopped (3): goal_reached                       -> v = omega = steering_angle = 0
 *   recover (2): steering_dir is NaN (nothing free)  -> differential drive: turn on the spot,
 *                v = 0, omega = +-recovery_angular_velocity toward the side that was last free;
 *                bicycle (cannot turn on the spot): reverse at recovery_linear_velocity with full
 *                lock away from that side, so the nose swings toward it. Once entered, recovery
 *                lasts at least recovery_min_duration (0: it ends as soon as a direction is free),
 *                with the side frozen: a car must back off far enough that what blocked it is
 *                beyond VFH's lower distance limit again, or VFH, blind below that limit, calls the
 *                way free while the obstacle is still right ahead.
 *   avoid   (1): |steering_dir - target_dir| > direction_tolerance
 *                -> differential drive: omega = avoid_gain * steering_dir (MathWorks' example);
 *                bicycle: steering_angle = avoid_steering_gain * steering_dir (the thesis's car
 *                takes "the steering angle that the Vector Field Histogram generates", section
 *                4.4.2); both: v = avoid_speed_factor * v_in
 *                With avoid_hold_time > 0 the avoidance outlives VFH's intervention: for that long
 *                after VFH calls the target free again the vehicle keeps heading at the last
 *                offset steering_dir - target_dir from the (moving) target direction. A sparse
 *                lidar (the thesis's car has three beams) loses an obstacle as soon as the vehicle
 *                turns away from it; without the hold the path follower steers straight back into it.
 *   follow  (0): otherwise the pure-pursuit (v_in, omega_in) is kept.
 *
 * For the bicycle a (v, omega) command becomes a steering angle atan2(omega * wheelbase, v), folded
 * into (-pi/2, pi/2] (MATLAB's bicycleKinematics conversion); every steering angle is clipped to
 * +-max_steering_angle, and the omega output is the yaw rate that angle gives,
 * v tan(steering_angle) / wheelbase. For the differential drive steering_angle is 0.
 */
#include <math.h>

#include "angles.h"
#include "config.h"
#include "model.h"
#include "model_binding.h" /* generated: what the glue, compiled once for every model, needs to know of this one */

void model_set_start_values(ModelData *data) {
    data->vehicle_type = VEHICLE_DIFFERENTIAL;
    data->wheelbase = 1.0;              /* bicycleKinematics default */
    data->max_steering_angle = M_PI / 4; /* bicycleKinematics default */
    data->direction_tolerance = 0.1;    /* MathWorks' PP + VFH example */
    data->avoid_gain = 0.5;             /* MathWorks' PP + VFH example */
    data->avoid_speed_factor = 1.0;
    data->recovery_angular_velocity = 0.5;
    data->recovery_linear_velocity = 0.1;
    data->avoid_steering_gain = 1.0;
    data->recovery_min_duration = 0.0;
    data->avoid_hold_time = 0.0;
    data->v_in = data->omega_in = data->target_dir = data->steering_dir = 0.0;
    data->goal_reached = false;
    data->v = data->omega = data->steering_angle = 0.0;
    data->mode = MODE_FOLLOW;
    data->recovery_sign = 1.0;
    data->recovery_elapsed = 0.0;
    data->avoid_offset = 0.0;
    data->hold_elapsed = INFINITY;
}

static double clip_to_lock(const ModelData *data, double angle) {
    if (angle > data->max_steering_angle) return data->max_steering_angle;
    if (angle < -data->max_steering_angle) return -data->max_steering_angle;
    return angle;
}

/* Bicycle steering angle for (v, omega): folded into (-pi/2, pi/2], clipped to the lock. */
static double steering_angle_for(const ModelData *data, double v, double omega) {
    return clip_to_lock(data, fold_to_half_pi(atan2(omega * data->wheelbase, v)));
}

/* Evaluate the rule for the current inputs, for outputs held over a step of h seconds.
 * `recovery_sign` remembers the last free side (frozen while a recovery holds). */
static void compute_outputs(ModelData *data, double *recovery_sign, double h) {
    const bool bicycle = data->vehicle_type == VEHICLE_BICYCLE;
    double v = data->v_in, omega = data->omega_in;
    const bool recovering = data->mode == MODE_RECOVER;
    /* 1e-9 h: a duration that is a whole number of steps is not lengthened by rounding. */
    const bool holding = recovering && data->recovery_elapsed < data->recovery_min_duration - 1e-9 * h;
    if (!holding && !isnan(data->steering_dir) && data->steering_dir != 0.0)
        *recovery_sign = data->steering_dir > 0 ? 1.0 : -1.0;

    if (data->goal_reached) {
        data->mode = MODE_STOPPED;
        data->v = data->omega = data->steering_angle = 0.0;
        data->recovery_elapsed = 0.0;
        data->hold_elapsed = INFINITY;
        return;
    }
    if (isnan(data->steering_dir) || holding) {
        data->recovery_elapsed = recovering ? data->recovery_elapsed + h : h;
        data->hold_elapsed = INFINITY; /* a recovery ends any held avoidance */
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
    data->recovery_elapsed = 0.0;
    double steering_angle;
    const double offset = wrap_to_pi(data->steering_dir - data->target_dir);
    double avoid_dir = NAN;
    if (fabs(offset) > data->direction_tolerance) {
        avoid_dir = data->steering_dir;
        data->avoid_offset = offset;
        data->hold_elapsed = 0.0;
    } else if (data->hold_elapsed < data->avoid_hold_time - 1e-9 * h) {
        avoid_dir = wrap_to_pi(data->target_dir + data->avoid_offset);
        data->hold_elapsed += h;
    }
    if (!isnan(avoid_dir)) {
        data->mode = MODE_AVOID;
        v = data->avoid_speed_factor * data->v_in;
        omega = data->avoid_gain * avoid_dir;
        steering_angle = clip_to_lock(data, data->avoid_steering_gain * avoid_dir);
    } else {
        data->mode = MODE_FOLLOW;
        steering_angle = bicycle ? steering_angle_for(data, v, omega) : 0.0;
    }
    data->v = v;
    if (bicycle) {
        data->steering_angle = steering_angle;
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
    if (!isfinite(data->avoid_gain) || !isfinite(data->avoid_speed_factor) ||
        !isfinite(data->avoid_steering_gain)) {
        model_log_error(comp,
                        "avoid_gain, avoid_speed_factor and avoid_steering_gain must be finite, "
                        "got %g, %g and %g",
                        data->avoid_gain, data->avoid_speed_factor, data->avoid_steering_gain);
        return MODEL_ERROR;
    }
    if (!(data->avoid_hold_time >= 0.0) || !isfinite(data->avoid_hold_time)) {
        model_log_error(comp, "avoid_hold_time must be finite and >= 0, got %g", data->avoid_hold_time);
        return MODEL_ERROR;
    }
    if (!(data->recovery_min_duration >= 0.0) || !isfinite(data->recovery_min_duration)) {
        model_log_error(comp, "recovery_min_duration must be finite and >= 0, got %g",
                        data->recovery_min_duration);
        return MODEL_ERROR;
    }
    /* Outputs at the start time; the recovery clock starts with the first step. */
    double recovery_sign = data->recovery_sign;
    compute_outputs(data, &recovery_sign, 0.0);
    data->recovery_elapsed = 0.0;
    return MODEL_OK;
}

ModelStatus model_do_step(ModelInstance *comp, ModelData *data, double t, double h) {
    (void)comp;
    (void)t;
    compute_outputs(data, &data->recovery_sign, h);
    return MODEL_OK;
}

double *model_real(ModelData *d, unsigned vr) {
    switch (vr) {
    case VR_WHEELBASE: return &d->wheelbase;
    case VR_MAX_STEERING_ANGLE: return &d->max_steering_angle;
    case VR_DIRECTION_TOLERANCE: return &d->direction_tolerance;
    case VR_AVOID_GAIN: return &d->avoid_gain;
    case VR_AVOID_SPEED_FACTOR: return &d->avoid_speed_factor;
    case VR_RECOVERY_ANGULAR_VELOCITY: return &d->recovery_angular_velocity;
    case VR_RECOVERY_LINEAR_VELOCITY: return &d->recovery_linear_velocity;
    case VR_AVOID_STEERING_GAIN: return &d->avoid_steering_gain;
    case VR_AVOID_HOLD_TIME: return &d->avoid_hold_time;
    case VR_RECOVERY_MIN_DURATION: return &d->recovery_min_duration;
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

int *model_integer(ModelData *d, unsigned vr) {
    switch (vr) {
    case VR_VEHICLE_TYPE: return &d->vehicle_type;
    case VR_MODE: return &d->mode;
    default: return NULL;
    }
}

bool *model_boolean(ModelData *d, unsigned vr) { return vr == VR_GOAL_REACHED ? &d->goal_reached : NULL; }
