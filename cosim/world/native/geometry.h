/* Point-polygon geometry shared by the lidar (is the sensor inside an obstacle?) and the exact
 * clearance (distance to the true obstacles); see cosim/world/geometry.py. The costmap
 * (cosim/navigation/native/costmap.c) includes it for the min/max below.
 *
 * A polygon is rows `first` to `stop - 1` of an (N, 2) row-major vertex array, closed implicitly,
 * so many polygons share one array. `py_min`/`py_max` are Python's two-argument min/max
 * (min(a, b) is b only when b < a), kept so that NaN and signed zeros come out as they always did. */
#ifndef COSIM_WORLD_GEOMETRY_H
#define COSIM_WORLD_GEOMETRY_H

#include <math.h>
#include <stdint.h>

static inline double py_min(double a, double b) { return b < a ? b : a; }
static inline double py_max(double a, double b) { return b > a ? b : a; }
static inline int64_t int_min(int64_t a, int64_t b) { return b < a ? b : a; }
static inline int64_t int_max(int64_t a, int64_t b) { return b > a ? b : a; }

/* Even-odd rule; a point on an edge may fall either way (its distance is 0 anyway). */
static inline int inside_polygon(double x, double y, const double *vertices, int64_t first, int64_t stop)
{
    int inside = 0;
    for (int64_t index = first; index < stop; index++) {
        double ax = vertices[2 * index], ay = vertices[2 * index + 1];
        int64_t following = index + 1 < stop ? index + 1 : first;
        double bx = vertices[2 * following], by = vertices[2 * following + 1];
        if ((ay > y) != (by > y) && x < ax + (y - ay) * (bx - ax) / (by - ay))
            inside = !inside;
    }
    return inside;
}

/* Exact distance [m] from (x, y) to the polygon's boundary; 0 inside it. */
static inline double polygon_distance(double x, double y, const double *vertices, int64_t first, int64_t stop)
{
    if (inside_polygon(x, y, vertices, first, stop))
        return 0.0;
    double nearest = INFINITY;
    for (int64_t index = first; index < stop; index++) {
        double ax = vertices[2 * index], ay = vertices[2 * index + 1];
        int64_t following = index + 1 < stop ? index + 1 : first;
        double dx = vertices[2 * following] - ax, dy = vertices[2 * following + 1] - ay;
        double length_sq = dx * dx + dy * dy;
        double t = length_sq == 0 ? 0.0 : py_min(1.0, py_max(0.0, ((x - ax) * dx + (y - ay) * dy) / length_sq));
        nearest = py_min(nearest, hypot(x - ax - t * dx, y - ay - t * dy));
    }
    return nearest;
}

#endif
