/*
 * Differential drive kinematics, integrated exactly: with constant wheel speeds over a step the
 * robot drives an arc (eq 4.4), so the pose follows the arc's closed form, not an Euler step.
 *
 * v/omega commands are converted to wheel speeds (eq 4.5), clipped to the wheel-speed range and
 * converted back (as MATLAB's differentialDriveKinematics), so a command the wheels cannot follow
 * becomes the motion they can.
 */
#include <math.h>

#include "config.h"
#include "model.h"
#include "planar_motion.h"
#include "model_binding.h" /* generated: what the glue, compiled once for every model, needs to know of this one */

void model_set_start_values(ModelData *m) {
    m->input_mode = INPUT_VELOCITIES;
    m->wheel_radius = 0.05;
    m->track_width = 0.2;
    m->wheel_speed_min = -INFINITY;
    m->wheel_speed_max = INFINITY;
    m->x0 = m->y0 = m->theta0 = 0.0;
    m->v = m->omega = m->wheel_speed_left = m->wheel_speed_right = 0.0;
}

static double clip(double value, double low, double high) { return value < low ? low : (value > high ? high : value); }

/* Wheel speeds the robot applies for the current inputs, then v and omega from eq 4.4. */
static ModelStatus apply_inputs(ModelInstance *comp, ModelData *m) {
    double left, right;
    if (m->input_mode == INPUT_VELOCITIES) {
        left = (m->v - m->omega * m->track_width / 2.0) / m->wheel_radius; /* eq 4.5 */
        right = (m->v + m->omega * m->track_width / 2.0) / m->wheel_radius;
    } else {
        left = m->wheel_speed_left;
        right = m->wheel_speed_right;
    }
    left = clip(left, m->wheel_speed_min, m->wheel_speed_max);
    right = clip(right, m->wheel_speed_min, m->wheel_speed_max);
    if (!isfinite(left) || !isfinite(right)) {
        model_log_error(comp, "inputs give non-finite wheel speeds (left %g, right %g rad/s)", left, right);
        return MODEL_ERROR;
    }
    m->wheel_speed_left_actual = left;
    m->wheel_speed_right_actual = right;
    m->v_actual = m->wheel_radius * (right + left) / 2.0; /* eq 4.4 */
    m->omega_actual = m->wheel_radius * (right - left) / m->track_width;
    return MODEL_OK;
}

ModelStatus model_initialize(ModelInstance *comp, ModelData *m) {
    if (!(m->wheel_radius > 0.0) || !isfinite(m->wheel_radius)) {
        model_log_error(comp, "parameter wheel_radius must be > 0 m, got %g", m->wheel_radius);
        return MODEL_ERROR;
    }
    if (!(m->track_width > 0.0) || !isfinite(m->track_width)) {
        model_log_error(comp, "parameter track_width must be > 0 m, got %g", m->track_width);
        return MODEL_ERROR;
    }
    if (!(m->wheel_speed_min <= m->wheel_speed_max)) {
        model_log_error(comp, "parameter wheel_speed_min (%g) must be <= wheel_speed_max (%g) rad/s",
                        m->wheel_speed_min, m->wheel_speed_max);
        return MODEL_ERROR;
    }
    if (m->input_mode != INPUT_VELOCITIES && m->input_mode != INPUT_WHEEL_SPEEDS) {
        model_log_error(comp, "parameter input_mode must be 0 (v/omega) or 1 (wheel speeds), got %d", m->input_mode);
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
    planar_advance(&m->x, &m->y, &m->theta, m->v_actual, 0.0, m->omega_actual, h);
    return MODEL_OK;
}

double *model_real(ModelData *m, unsigned vr) {
    switch (vr) {
    case VR_WHEEL_RADIUS: return &m->wheel_radius;
    case VR_TRACK_WIDTH: return &m->track_width;
    case VR_WHEEL_SPEED_MIN: return &m->wheel_speed_min;
    case VR_WHEEL_SPEED_MAX: return &m->wheel_speed_max;
    case VR_X0: return &m->x0;
    case VR_Y0: return &m->y0;
    case VR_THETA0: return &m->theta0;
    case VR_V: return &m->v;
    case VR_OMEGA: return &m->omega;
    case VR_WHEEL_SPEED_LEFT: return &m->wheel_speed_left;
    case VR_WHEEL_SPEED_RIGHT: return &m->wheel_speed_right;
    case VR_X: return &m->x;
    case VR_Y: return &m->y;
    case VR_THETA: return &m->theta;
    case VR_V_ACTUAL: return &m->v_actual;
    case VR_OMEGA_ACTUAL: return &m->omega_actual;
    case VR_WHEEL_SPEED_LEFT_ACTUAL: return &m->wheel_speed_left_actual;
    case VR_WHEEL_SPEED_RIGHT_ACTUAL: return &m->wheel_speed_right_actual;
    default: return NULL;
    }
}

int *model_integer(ModelData *m, unsigned vr) { return vr == VR_INPUT_MODE ? &m->input_mode : NULL; }

bool *model_boolean(ModelData *m, unsigned vr) {
    (void)m;
    (void)vr;
    return NULL;
}
