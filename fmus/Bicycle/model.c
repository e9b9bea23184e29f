/*
 * Kinematic bicycle (thesis eqs 4.6-4.11), integrated exactly.
 *
 * Conventions. Angles are counter-clockwise positive. `v` is the longitudinal speed (along the
 * body axis, the same at every point of it; the rear-axle speed for front steering, as MATLAB).
 * `steering_angle` is the front wheel's angle delta_f; the rear wheel's angle delta_r, measured
 * the same way, follows from the mode:
 *   front steering (eq 4.11)  delta_r = 0
 *   zero sideslip  (eq 4.9)   delta_r = -delta_f: the rear counter-steers, the ICR lies level with
 *                             the wheelbase midpoint, which moves without sideslip
 *   parallel       (eq 4.10)  delta_r = +delta_f: both axles steer the same way, the body crabs
 *                             at angle delta_f without yawing
 * With no lateral wheel slip, the yaw rate is r = v (tan delta_f - tan delta_r) / L, and a point a
 * distance s ahead of the rear axle moves at slip angle beta = atan(((L-s) tan delta_r + s tan delta_f)/L)
 * (eq 4.7 with l_r = s, l_f = L - s) and speed v / cos(beta). For constant inputs over a step that
 * velocity is constant in the body frame, so the reference point follows a circular arc.
 *
 * Input (v, omega) is converted to the steering angle that gives yaw rate omega in the chosen
 * mode: atan2(omega L, v) for front steering (MATLAB), atan2(omega L, 2 v) for zero sideslip,
 * folded into (-pi/2, pi/2]. Parallel steering cannot yaw, so that combination is rejected.
 */
#include <math.h>

#include "angles.h"
#include "config.h"
#include "model.h"
#include "planar_motion.h"
#include "model_binding.h" /* generated: what the glue, compiled once for every model, needs to know of this one */

void model_set_start_values(ModelData *m) {
    m->input_mode = INPUT_STEERING_ANGLE;
    m->steering_mode = STEERING_FRONT;
    m->wheelbase = 1.0;
    m->rear_axle_distance = 0.0;
    m->max_steering_angle = M_PI / 4.0;
    m->speed_min = -INFINITY;
    m->speed_max = INFINITY;
    m->x0 = m->y0 = m->theta0 = 0.0;
    m->v = m->steering_angle = m->omega = 0.0;
}

static double clip(double value, double low, double high) { return value < low ? low : (value > high ? high : value); }

/* Steering angle giving yaw rate omega at longitudinal speed v, folded into (-pi/2, pi/2]. */
static double steering_for_yaw_rate(const ModelData *m, double v, double omega) {
    double divisor = m->steering_mode == STEERING_ZERO_SIDESLIP ? 2.0 : 1.0;
    return fold_to_half_pi(atan2(omega * m->wheelbase, divisor * v));
}

static ModelStatus apply_inputs(ModelInstance *comp, ModelData *m) {
    double v = clip(m->v, m->speed_min, m->speed_max);
    double steering, tan_front, tan_rear, tan_slip;
    if (!isfinite(v)) {
        model_log_error(comp, "input v gives a non-finite speed (%g m/s)", v);
        return MODEL_ERROR;
    }
    steering = m->input_mode == INPUT_YAW_RATE ? steering_for_yaw_rate(m, v, m->omega) : m->steering_angle;
    if (isnan(steering)) {
        model_log_error(comp, "input %s is NaN", m->input_mode == INPUT_YAW_RATE ? "omega" : "steering_angle");
        return MODEL_ERROR;
    }
    steering = clip(steering, -m->max_steering_angle, m->max_steering_angle);
    tan_front = tan(steering);
    tan_rear = m->steering_mode == STEERING_FRONT ? 0.0
               : m->steering_mode == STEERING_ZERO_SIDESLIP ? -tan_front
                                                            : tan_front;
    tan_slip = ((m->wheelbase - m->rear_axle_distance) * tan_rear + m->rear_axle_distance * tan_front) / m->wheelbase;
    m->v_actual = v;
    m->steering_angle_actual = steering;
    m->yaw_rate = v * (tan_front - tan_rear) / m->wheelbase;
    m->slip_angle = atan(tan_slip);
    m->point_speed = v * sqrt(1.0 + tan_slip * tan_slip); /* v / cos(beta) */
    return MODEL_OK;
}

ModelStatus model_initialize(ModelInstance *comp, ModelData *m) {
    if (!(m->wheelbase > 0.0) || !isfinite(m->wheelbase)) {
        model_log_error(comp, "parameter wheelbase must be > 0 m, got %g", m->wheelbase);
        return MODEL_ERROR;
    }
    if (!(m->max_steering_angle > 0.0 && m->max_steering_angle < M_PI / 2.0)) {
        model_log_error(comp, "parameter max_steering_angle must be in (0, pi/2) rad, got %g", m->max_steering_angle);
        return MODEL_ERROR;
    }
    if (!(m->speed_min <= m->speed_max)) {
        model_log_error(comp, "parameter speed_min (%g) must be <= speed_max (%g) m/s", m->speed_min, m->speed_max);
        return MODEL_ERROR;
    }
    if (!isfinite(m->rear_axle_distance)) {
        model_log_error(comp, "parameter rear_axle_distance must be finite, got %g", m->rear_axle_distance);
        return MODEL_ERROR;
    }
    if (m->steering_mode < STEERING_FRONT || m->steering_mode > STEERING_PARALLEL) {
        model_log_error(comp, "parameter steering_mode must be 0 (front), 1 (zero sideslip) or 2 (parallel), got %d",
                        m->steering_mode);
        return MODEL_ERROR;
    }
    if (m->input_mode != INPUT_STEERING_ANGLE && m->input_mode != INPUT_YAW_RATE) {
        model_log_error(comp, "parameter input_mode must be 0 (v/steering_angle) or 1 (v/omega), got %d",
                        m->input_mode);
        return MODEL_ERROR;
    }
    if (m->input_mode == INPUT_YAW_RATE && m->steering_mode == STEERING_PARALLEL) {
        model_log_error(comp, "parameter input_mode 1 (v/omega) is impossible with steering_mode 2: parallel "
                              "steering cannot yaw");
        return MODEL_ERROR;
    }
    if (!planar_start_pose(comp, m->x0, m->y0, m->theta0, &m->x, &m->y, &m->theta)) {
        return MODEL_ERROR;
    }
    return apply_inputs(comp, m);
}

ModelStatus model_do_step(ModelInstance *comp, ModelData *m, double t, double h) {
    (void)t;
    if (apply_inputs(comp, m) != MODEL_OK) {
        return MODEL_ERROR;
    }
    planar_advance(&m->x, &m->y, &m->theta, m->point_speed, m->slip_angle, m->yaw_rate, h);
    return MODEL_OK;
}

double *model_real(ModelData *m, unsigned vr) {
    switch (vr) {
    case VR_WHEELBASE: return &m->wheelbase;
    case VR_REAR_AXLE_DISTANCE: return &m->rear_axle_distance;
    case VR_MAX_STEERING_ANGLE: return &m->max_steering_angle;
    case VR_SPEED_MIN: return &m->speed_min;
    case VR_SPEED_MAX: return &m->speed_max;
    case VR_X0: return &m->x0;
    case VR_Y0: return &m->y0;
    case VR_THETA0: return &m->theta0;
    case VR_V: return &m->v;
    case VR_STEERING_ANGLE: return &m->steering_angle;
    case VR_OMEGA: return &m->omega;
    case VR_X: return &m->x;
    case VR_Y: return &m->y;
    case VR_THETA: return &m->theta;
    case VR_V_ACTUAL: return &m->v_actual;
    case VR_STEERING_ANGLE_ACTUAL: return &m->steering_angle_actual;
    case VR_YAW_RATE: return &m->yaw_rate;
    case VR_SLIP_ANGLE: return &m->slip_angle;
    default: return NULL;
    }
}

int *model_integer(ModelData *m, unsigned vr) {
    switch (vr) {
    case VR_INPUT_MODE: return &m->input_mode;
    case VR_STEERING_MODE: return &m->steering_mode;
    default: return NULL;
    }
}

bool *model_boolean(ModelData *m, unsigned vr) {
    (void)m;
    (void)vr;
    return NULL;
}
