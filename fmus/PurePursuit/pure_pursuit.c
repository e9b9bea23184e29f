/*
 * Pure pursuit as MATLAB's controllerPurePursuit computes it: a projection point that only moves
 * forward, an arc-length lookahead from it, omega = 2 sin(alpha) / L.
 */
#include "pure_pursuit.h"

#include <float.h>
#include <math.h>

void pure_pursuit_compact_path(ModelData *data) {
    int count = 0;
    for (int k = 0; k < PP_MAX_WAYPOINTS; k++) {
        if (isnan(data->waypoints_x[k]) || isnan(data->waypoints_y[k])) continue;
        data->path_x[count] = data->waypoints_x[k];
        data->path_y[count] = data->waypoints_y[k];
        count++;
    }
    data->path_count = count;
}

/* Euclidean length; sqrt rather than hypot, which is several times slower and guards only
 * against overflow far beyond map coordinates. */
static double length(double dx, double dy) { return sqrt(dx * dx + dy * dy); }

/* Closest point to (px, py) on the segment a-b; returns its distance. */
static double closest_point_on_segment(double ax, double ay, double bx, double by, double px, double py,
                                       double *cx, double *cy) {
    double dx = bx - ax, dy = by - ay;
    double length_squared = dx * dx + dy * dy;
    double t = 0.0;
    if (length_squared > 0.0) {
        t = ((px - ax) * dx + (py - ay) * dy) / length_squared;
        t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
    }
    *cx = ax + t * dx;
    *cy = ay + t * dy;
    return length(px - *cx, py - *cy);
}

/* Search forward from the current segment; stop once the path length walked since the old
 * projection point exceeds the lookahead, unless this is the first search (all segments). */
static void update_projection(const ModelData *data, ProjectionState *projection) {
    const double *path_x = data->path_x, *path_y = data->path_y;
    const int last = data->path_count - 1;
    bool search_all = !projection->valid;
    if (search_all) {
        projection->valid = true;
        projection->segment = 0;
        projection->x = path_x[0];
        projection->y = path_y[0];
    }
    int segment = projection->segment;
    double min_distance = closest_point_on_segment(projection->x, projection->y, path_x[segment + 1],
                                                   path_y[segment + 1], data->x, data->y,
                                                   &projection->x, &projection->y);
    double walked = length(projection->x - path_x[segment + 1], projection->y - path_y[segment + 1]);
    for (int i = segment + 1; i < last; i++) {
        if (!search_all && walked > data->lookahead_distance) break;
        walked += length(path_x[i + 1] - path_x[i], path_y[i + 1] - path_y[i]);
        double cx, cy;
        double distance = closest_point_on_segment(path_x[i], path_y[i], path_x[i + 1], path_y[i + 1],
                                                   data->x, data->y, &cx, &cy);
        if (distance < min_distance) {
            min_distance = distance;
            projection->x = cx;
            projection->y = cy;
            projection->segment = i;
        }
    }
}

void pure_pursuit_lookahead(const ModelData *data, ProjectionState *projection, double *lookahead_x,
                            double *lookahead_y) {
    const double *path_x = data->path_x, *path_y = data->path_y;
    const int last = data->path_count - 1;
    if (last == 0) {
        projection->valid = true;
        projection->segment = 0;
        *lookahead_x = projection->x = path_x[0];
        *lookahead_y = projection->y = path_y[0];
        return;
    }
    update_projection(data, projection);

    /* Walk along the path from the projection point until the arc length reaches L. */
    int segment = projection->segment;
    double start_x = projection->x, start_y = projection->y;
    double end_x = path_x[segment + 1], end_y = path_y[segment + 1];
    double walked = length(end_x - start_x, end_y - start_y);
    double overshoot = walked - data->lookahead_distance;
    while (overshoot < 0.0 && segment < last - 1) {
        segment++;
        start_x = path_x[segment];
        start_y = path_y[segment];
        end_x = path_x[segment + 1];
        end_y = path_y[segment + 1];
        walked += length(end_x - start_x, end_y - start_y);
        overshoot = walked - data->lookahead_distance;
    }
    /* overshoot > 0: the point lies `overshoot` back from the segment end; otherwise the path
     * ended before the lookahead was used up and the last waypoint is the target. */
    double segment_length = length(end_x - start_x, end_y - start_y);
    if (overshoot > 0.0 && segment_length > 0.0) {
        double back = overshoot / segment_length;
        *lookahead_x = (1.0 - back) * end_x + back * start_x;
        *lookahead_y = (1.0 - back) * end_y + back * start_y;
    } else {
        *lookahead_x = end_x;
        *lookahead_y = end_y;
    }
}

static double sign(double value) { return value > 0.0 ? 1.0 : (value < 0.0 ? -1.0 : value); }

double pure_pursuit_angular_velocity(const ModelData *data, double alpha) {
    /* Curvature of the arc through the lookahead point [1/m]. */
    double curvature = 2.0 * sin(alpha) / data->lookahead_distance;
    /* With the target straight behind, sin(alpha) ~ 0 would never turn the robot around:
     * MATLAB turns at 1 rad/s instead, in the direction of the rounding. */
    if (fabs(fabs(alpha) - M_PI) < sqrt(DBL_EPSILON)) curvature = sign(curvature);
    /* MATLAB outputs the curvature as rad/s (exact at 1 m/s); nav2 scales it by the speed. */
    double omega = data->angular_velocity_law == 1 ? data->desired_linear_velocity * curvature : curvature;
    if (fabs(omega) > data->max_angular_velocity) omega = sign(omega) * data->max_angular_velocity;
    return omega;
}
