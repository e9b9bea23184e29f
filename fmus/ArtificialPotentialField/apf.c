/*
 * Artificial potential field (Khatib 1986; thesis section 2.3.1, its future work in chapter 5) on
 * a lidar scan, in the vehicle frame (x ahead, y to the left), with VFH's ports:
 *
 *   attraction  F_att = attractive_gain * (cos t, sin t), a constant pull toward the target
 *               direction t = target_dir (the pure-pursuit lookahead bearing; NaN counts as 0,
 *               as in VFH). Its strength does not depend on the distance to the target: the
 *               lookahead point moves with the vehicle.
 *   repulsion   every reading i inside the distance limits whose clearance from the vehicle's
 *               circle, rho_i = range_i - robot_radius, is below rho_0 = influence_distance pushes
 *               the vehicle straight away from it with Khatib's magnitude
 *                   |F_i| = repulsive_gain * (1 / rho_i - 1 / rho_0) / rho_i^2,
 *               F_i = -|F_i| (cos a_i, sin a_i). rho_i is floored at MIN_CLEARANCE, so a reading
 *               inside the circle repels hard but finitely. The sum runs over readings, not
 *               obstacles: a denser lidar sees more readings of the same box, so repulsive_gain
 *               scales with the beams per radian (as VFH's thresholds do).
 *   steering    s = atan2 of F = F_att + sum F_i; with no repelling reading exactly t.
 *
 * A reading closer than robot_radius + safety_distance (inside the safety circle) blocks every
 * direction within 90 degrees of it, as VFH's enlargement angle does for such a reading: driving
 * that way closes in on it. `direction_status` says what steering_dir is:
 *   0 force     the direction of F;
 *   1 deflected F's direction is blocked: the nearest direction no such reading blocks;
 *   2 trapped   no direction (NaN): F = 0, or F points farther than max_target_deviation from t
 *               (the local minimum in front of an obstacle; the default pi never counts it, since
 *               following F out of a shallow minimum beats giving up: the field of a 360-degree
 *               scan does not change while the mixer turns the vehicle on the spot);
 *   3 enclosed  no direction (NaN): the safety-circle readings block every direction (VFH's
 *               "nothing free").
 * On NaN the mixer recovers as it does for VFH.
 * target_dir_free: no repelling reading lies in the corridor of half-width robot_radius +
 * safety_distance ahead along t.
 */
#include "apf.h"

#include <math.h>

#define MIN_CLEARANCE 1e-3 /* m: the smallest clearance the repulsion is evaluated at */

static void update_reading_angles(ModelData *data) {
    for (int i = 0; i < APF_MAX_READINGS; i++) {
        data->reading_cos[i] = cos(data->angles[i]);
        data->reading_sin[i] = sin(data->angles[i]);
    }
    data->angles_changed = false;
}

/* A reading counts when its range lies inside the distance limits (NaN fails the test). */
static bool reading_is_valid(const ModelData *data, int i) {
    const double range = data->ranges[i];
    return range >= data->distance_limit_min && range <= data->distance_limit_max &&
           isfinite(data->angles[i]);
}

/* Khatib's repulsive magnitude at clearance rho < rho_0. */
static double repulsion(const ModelData *data, double clearance) {
    const double rho = clearance > MIN_CLEARANCE ? clearance : MIN_CLEARANCE;
    return data->repulsive_gain * (1.0 / rho - 1.0 / data->influence_distance) / (rho * rho);
}

/* Driving along the unit vector (x, y) closes in on a reading inside the safety circle: it lies
 * within 90 degrees of the direction. The cosine must exceed PERPENDICULAR, not 0, so that what
 * is perpendicular up to rounding (a wall beside the vehicle, or a deflected direction beside its
 * reading) does not block. */
#define PERPENDICULAR 1e-12
static bool heads_into_safety_circle(const ModelData *data, int close, double x, double y) {
    for (int k = 0; k < close; k++) {
        const int i = data->close_readings[k];
        if (data->reading_cos[i] * x + data->reading_sin[i] * y > PERPENDICULAR) return true;
    }
    return false;
}

/* Replace the unit vector (x, y) by the nearest direction that heads into no safety-circle
 * reading; false when there is none. The free directions are an intersection of closed half
 * circles, one per close reading, so the nearest one to a blocked direction is an end of one of
 * them: a reading's angle +- 90 degrees. */
static bool deflect(const ModelData *data, int close, double *x, double *y) {
    double best_x = 0.0, best_y = 0.0, best_cos = -INFINITY;
    for (int k = 0; k < close; k++) {
        const int i = data->close_readings[k];
        const double c = data->reading_cos[i], s = data->reading_sin[i];
        const double ends[2][2] = {{-s, c}, {s, -c}}; /* angle + 90 and - 90 degrees */
        for (int e = 0; e < 2; e++) {
            const double alignment = ends[e][0] * *x + ends[e][1] * *y;
            if (alignment <= best_cos) continue;
            if (heads_into_safety_circle(data, close, ends[e][0], ends[e][1])) continue;
            best_x = ends[e][0];
            best_y = ends[e][1];
            best_cos = alignment;
        }
    }
    if (best_cos == -INFINITY) return false;
    *x = best_x;
    *y = best_y;
    return true;
}

void apf_step(ModelData *data) {
    if (data->angles_changed) update_reading_angles(data);
    const double target = isnan(data->target_dir) ? 0.0 : wrap_to_pi(data->target_dir);
    const double target_cos = cos(target), target_sin = sin(target);
    const double safety_radius = data->robot_radius + data->safety_distance;

    double force_x = data->attractive_gain * target_cos, force_y = data->attractive_gain * target_sin;
    double nearest = NAN;
    int repelling = 0, close = 0;
    bool target_free = true;
    for (int i = 0; i < APF_MAX_READINGS; i++) {
        if (!reading_is_valid(data, i)) continue;
        const double range = data->ranges[i], c = data->reading_cos[i], s = data->reading_sin[i];
        if (!(range >= nearest)) nearest = range; /* the first valid reading replaces NaN */
        if (range < safety_radius) data->close_readings[close++] = i;
        const double clearance = range - data->robot_radius;
        if (!(clearance < data->influence_distance)) continue;
        const double magnitude = repulsion(data, clearance);
        force_x -= magnitude * c;
        force_y -= magnitude * s;
        repelling++;
        /* Along-track and cross-track position of the reading relative to the target ray. */
        const double along = range * (c * target_cos + s * target_sin);
        const double across = range * (s * target_cos - c * target_sin);
        if (along > 0.0 && fabs(across) < safety_radius) target_free = false;
    }

    int status = APF_FORCE;
    double steering = target;
    if (repelling > 0) {
        if (force_x == 0.0 && force_y == 0.0) status = APF_TRAPPED;
        else steering = atan2(force_y, force_x);
        if (fabs(wrap_to_pi(steering - target)) > data->max_target_deviation) status = APF_TRAPPED;
    }
    if (status == APF_FORCE && close > 0) {
        double direction_x = cos(steering), direction_y = sin(steering);
        if (heads_into_safety_circle(data, close, direction_x, direction_y)) {
            status = deflect(data, close, &direction_x, &direction_y) ? APF_DEFLECTED : APF_ENCLOSED;
            steering = atan2(direction_y, direction_x);
        }
    }
    data->steering_dir = status == APF_FORCE || status == APF_DEFLECTED ? steering : NAN;
    data->direction_status = status;
    data->force_x = force_x;
    data->force_y = force_y;
    data->nearest_distance = nearest;
    data->repelling_readings = repelling;
    data->target_dir_free = target_free;
}
