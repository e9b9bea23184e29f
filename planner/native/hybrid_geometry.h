/* Geometry of hybrid A*: Python's float modulo, angle wrapping, arcs and straights, and their
 * check against an occupancy grid. The C of planner/hybrid_geometry.py, operation for operation
 * (the library is built with -ffp-contract=off: no fused multiply-add). Included by hybrid.c. */
#ifndef NAVCOSIM_HYBRID_GEOMETRY_H
#define NAVCOSIM_HYBRID_GEOMETRY_H

#include <math.h>
#include <stdint.h>

#define HY_PI 3.141592653589793 /* math.pi, the double nearest to pi */
#define HY_TWO_PI (2.0 * HY_PI)
#define HY_HALF_PI (0.5 * HY_PI)

/* Python's float `a % b` (CPython's float_rem): the remainder takes the sign of b. */
static inline double hy_py_mod(double a, double b) {
    double mod = fmod(a, b);
    if (mod != 0.0 || mod != mod) {
        if ((b < 0.0) != (mod < 0.0)) mod += b;
    } else {
        mod = b < 0.0 ? -0.0 : 0.0;
    }
    return mod;
}

/* Python's max(a, b) and min(a, b) of two floats: b only if it compares greater (smaller). */
static inline double hy_max(double a, double b) { return b > a ? b : a; }
static inline double hy_min(double a, double b) { return b < a ? b : a; }

/* Angle [rad] wrapped into (-pi, pi]. */
static inline double hy_wrap_angle(double angle) { return HY_PI - hy_py_mod(HY_PI - angle, HY_TWO_PI); }

/* Pose reached after driving `signed_length` [m] at `curvature` [1/m] from (x, y, theta). */
static inline void hy_advance(double x, double y, double theta, double curvature, double signed_length,
                              double *out_x, double *out_y, double *out_theta) {
    if (curvature == 0.0) {
        *out_x = x + signed_length * cos(theta);
        *out_y = y + signed_length * sin(theta);
        *out_theta = theta;
        return;
    }
    double new_theta = theta + curvature * signed_length;
    *out_x = x + (sin(new_theta) - sin(theta)) / curvature;
    *out_y = y - (cos(new_theta) - cos(theta)) / curvature;
    *out_theta = new_theta;
}

/* An occupancy grid: rows x cols bytes (numpy bool), row 0 = top, and its placement. */
typedef struct {
    const uint8_t *occupied;
    int64_t rows, cols;
    double resolution, origin_x, origin_y;
} HyGrid;

/* True if the point (x, y) [m] lies in a free cell. */
static inline int hy_point_free(const HyGrid *grid, double x, double y) {
    int64_t col = (int64_t)floor((x - grid->origin_x) / grid->resolution);
    int64_t row_from_bottom = (int64_t)floor((y - grid->origin_y) / grid->resolution);
    int64_t row = grid->rows - 1 - row_from_bottom;
    if (row < 0 || row >= grid->rows || col < 0 || col >= grid->cols) return 0;
    return !grid->occupied[row * grid->cols + col];
}

/* True if every sample every <= `step` [m] along the segments lies in a free cell. */
static int hy_segments_free(const HyGrid *grid, double x, double y, double theta, const double *curvatures,
                            const double *signed_lengths, int64_t count, double step) {
    if (!hy_point_free(grid, x, y)) return 0;
    for (int64_t k = 0; k < count; k++) {
        double length = signed_lengths[k];
        if (length == 0.0) continue;
        int64_t pieces = (int64_t)ceil(fabs(length) / step - 1e-9);
        if (pieces < 1) pieces = 1;
        for (int64_t piece = 1; piece <= pieces; piece++) {
            double px, py, pt;
            hy_advance(x, y, theta, curvatures[k], length * (double)piece / (double)pieces, &px, &py, &pt);
            if (!hy_point_free(grid, px, py)) return 0;
        }
        hy_advance(x, y, theta, curvatures[k], length, &x, &y, &theta);
    }
    return 1;
}

#endif
