/* Kernels of cosim.world: the exact clearance (distance.py), the lidar's ray casting (lidar.py)
 * and the point-polygon geometry they share (geometry.h, exported for geometry.py).
 *
 * Built by native/load.py (C99, -ffp-contract=off, no fast-math): every floating-point
 * operation is the one the Python docstrings describe, in the same order, so the results are
 * those of the numba kernels these replaced, bit for bit. The long-lived arrays and constants of
 * a lidar or a world come in one struct set up once in Python (the `ctypes.Structure`s of
 * cosim/world/kernels.py mirror them field for field); a call passes its address and the pose. */
#ifdef __linux__
#define _GNU_SOURCE /* sched_getcpu, pthread_setaffinity_np (and POSIX's pthreads under -std=c99) */
#include <sched.h>
#else
#define _POSIX_C_SOURCE 200809L /* pthreads and getpid under -std=c99 */
#endif
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <unistd.h>

#include "geometry.h"
#include "pyhypot.h"
#include "../../../planner/native/layout.h"

double world_polygon_distance(double x, double y, const double *vertices, int64_t first, int64_t stop)
{
    return polygon_distance(x, y, vertices, first, stop);
}

/* ---------------------------------------------------------------- exact clearance (distance.py) */

typedef struct {
    const uint8_t *occupied; /* rows x cols, row 0 at the top (the grid's convention) */
    int64_t rows, cols;
    double x_min, y_min, x_max, y_max, resolution;
    const double *circles; /* n_circles x 3: cx, cy, r */
    int64_t n_circles;
    const double *vertices; /* polygon p is vertices[starts[p]:starts[p + 1]] */
    const int64_t *starts;
    int64_t n_starts;
    /* The query, written by the caller before each call (packing them costs Python less than
     * passing them as ctypes arguments): the point, the cell (row, col) holding it, its distance
     * `offset` [m] from that cell's centre and the cell's centre field value `field` (the distance
     * [m] from its centre to the nearest occupied centre). */
    double x, y;
    int64_t row, col;
    double offset, field;
} World;

/* Row r's part of `world_distance`: the squared distance from (x, y) to the nearest occupied
 * square of the row among columns c_first .. c_stop - 1 into *nearest_sq when smaller. The point
 * lies in column col: the squares left of it have their centres at least half a cell left of the
 * point, so the higher their column the nearer (monotonic in the computed values too), and those
 * right of it the lower their column; so besides col's own square (rounding may put it a hair
 * farther than its neighbour when the point is on their common side) the first occupied one each
 * way from col is the row's nearest on that side. Returns 0 when no square of the row can be
 * nearer than *nearest_sq (dx * dx + dy * dy >= dy * dy, rounded as well). */
/* The squared distance from x to the occupied square of column c of a row whose vertical gap
 * squared is dy_sq, into *nearest_sq when smaller. */
static inline void nearest_in_column(const World *w, int64_t c, double x, double half, double dy_sq,
                                     double *nearest_sq)
{
    double centre_x = w->x_min + ((double)c + 0.5) * w->resolution;
    double dx = py_max(fabs(centre_x - x) - half, 0.0);
    *nearest_sq = py_min(*nearest_sq, dx * dx + dy_sq);
}

static inline int nearest_in_row(const World *w, int64_t r, double x, double y, double half, int64_t col,
                                 int64_t c_first, int64_t c_stop, double *nearest_sq)
{
    double resolution = w->resolution;
    double centre_y = w->y_min + ((double)(w->rows - 1 - r) + 0.5) * resolution;
    double dy = py_max(fabs(centre_y - y) - half, 0.0);
    double dy_sq = dy * dy;
    if (!(dy_sq < *nearest_sq))
        return 0;
    const uint8_t *line = w->occupied + r * w->cols;
    if (line[col])
        nearest_in_column(w, col, x, half, dy_sq, nearest_sq);
    for (int64_t c = col - 1; c >= c_first; c--)
        if (line[c]) {
            nearest_in_column(w, c, x, half, dy_sq, nearest_sq);
            break;
        }
    for (int64_t c = col + 1; c < c_stop; c++)
        if (line[c]) {
            nearest_in_column(w, c, x, half, dy_sq, nearest_sq);
            break;
        }
    return 1;
}

/* `WorldDistance.distance` for a point inside the map (the query of `w`). */
double world_distance(const World *w)
{
    double x = w->x, y = w->y, offset = w->offset, field = w->field;
    int64_t row = w->row, col = w->col;
    /* The distance to the map edge: Python's min(x - x_min, x_max - x, y - y_min, y_max - y). */
    double best = py_min(py_min(py_min(x - w->x_min, w->x_max - x), y - w->y_min), w->y_max - y);
    double resolution = w->resolution;
    double half = resolution / 2.0;
    int64_t rows = w->rows, cols = w->cols;
    if (isfinite(field)) {
        /* The nearest centre's square is within field + offset; any square that close has its
         * centre within that plus a half diagonal, so a window of that reach holds the nearest one. */
        double reach = py_min(best, field + offset) + sqrt(2.0) * half;
        int64_t k = (int64_t)ceil(reach / resolution);
        double nearest_sq = INFINITY;
        int64_t r_first = int_max(row - k, 0), r_stop = int_min(row + k + 1, rows);
        int64_t c_first = int_max(col - k, 0), c_stop = int_min(col + k + 1, cols);
        /* The window's rows outward from the point's, up then down: the rows above it have their
         * centres at least half a cell above the point, so their distance dy grows the farther
         * the row (the computed one too: each operation is monotonic), and likewise below; once
         * a row's dy * dy >= nearest_sq no farther row on that side can lower it. The point's own
         * row (dy about 0, a hair more than a neighbour's by rounding on their common side)
         * stops neither side. */
        nearest_in_row(w, row, x, y, half, col, c_first, c_stop, &nearest_sq);
        for (int64_t r = row - 1; r >= r_first; r--)
            if (!nearest_in_row(w, r, x, y, half, col, c_first, c_stop, &nearest_sq))
                break;
        for (int64_t r = row + 1; r < r_stop; r++)
            if (!nearest_in_row(w, r, x, y, half, col, c_first, c_stop, &nearest_sq))
                break;
        best = py_min(best, sqrt(nearest_sq));
    }
    for (int64_t index = 0; index < w->n_circles; index++) {
        const double *circle = w->circles + 3 * index;
        double gap = hypot(x - circle[0], y - circle[1]) - circle[2];
        best = py_min(best, py_max(0.0, gap));
    }
    for (int64_t polygon = 0; polygon < w->n_starts - 1; polygon++)
        best = py_min(best, polygon_distance(x, y, w->vertices, w->starts[polygon], w->starts[polygon + 1]));
    return best;
}

/* Python's math.hypot (pyhypot.h), for the tests that compare it with Python's. */
double world_hypot(double x, double y)
{
    return py_hypot(x, y);
}

/* ------------------------------------------------- position checks (outcome.py check_positions) */

typedef struct {
    const World *world;        /* the grid and shapes of a static world (`WorldDistance`) */
    const double *centre_field; /* rows x cols: each cell centre's distance [m] to the nearest occupied centre */
    const double *bounds;      /* n_bounds x 3: bounding circles of the polygons, cx, cy, r */
    int64_t n_bounds;
    double radius, goal_x, goal_y, tolerance, speed;
    /* The monitor's state, read and written back: the last position, the distance driven, the
     * minimum clearance and the anchor of the lower bound (x, y, t, bound). */
    double last_x, last_y, distance, min_clearance;
    double anchor_x, anchor_y, anchor_t, anchor_bound;
    int64_t reason;       /* why the last call stopped: CHECK_* */
    const double *points; /* 3 x capacity: the steps' x, then y, then t (end of the step [s]) */
    int64_t capacity;
} Monitor;

enum { CHECK_GOING = 0, CHECK_COLLISION = 1, CHECK_GOAL = 2, CHECK_PYTHON = 3 };

/* The cell (row, col) of a point inside the map and its distance to the cell's centre, as
 * `WorldDistance._cell`; 0 when the cell is off the grid (rounding at the far edge), where Python
 * indexes out of bounds. */
static int world_cell(const World *w, double x, double y, int64_t *row, int64_t *col, double *offset)
{
    int64_t c = (int64_t)((x - w->x_min) / w->resolution);
    int64_t r = w->rows - 1 - (int64_t)((y - w->y_min) / w->resolution);
    if (c < 0 || c >= w->cols || r < 0 || r >= w->rows)
        return 0;
    double centre_x = w->x_min + ((double)c + 0.5) * w->resolution;
    double centre_y = w->y_min + ((double)(w->rows - 1 - r) + 0.5) * w->resolution;
    *row = r;
    *col = c;
    *offset = py_hypot(x - centre_x, y - centre_y);
    return 1;
}

static int inside_map(const World *w, double x, double y)
{
    return w->x_min <= x && x < w->x_max && w->y_min <= y && y < w->y_max;
}

/* `OutcomeMonitor.check_positions` for a static world and n <= capacity steps, the same operations
 * in the same order (Python's hypot, min and max): the index of the step that ends the run with
 * its reason in m->reason (CHECK_COLLISION, CHECK_GOAL), or n and CHECK_GOING; CHECK_PYTHON at a
 * step whose cell is off the grid (its state untouched: Python takes over there). */
int64_t world_check_positions(Monitor *m, int64_t n)
{
    const double *xs = m->points, *ys = m->points + m->capacity, *times = m->points + 2 * m->capacity;
    int64_t *reason = &m->reason;
    if (n > m->capacity) {
        *reason = CHECK_PYTHON;
        return 0;
    }
    const World *w = m->world;
    World query = *w;
    double half = w->resolution / 2.0;
    double last_x = m->last_x, last_y = m->last_y, distance = m->distance, min_clearance = m->min_clearance;
    double anchor_x = m->anchor_x, anchor_y = m->anchor_y, anchor_t = m->anchor_t, anchor_bound = m->anchor_bound;
    int64_t i = 0;
    *reason = CHECK_GOING;
    for (; i < n; i++) {
        double x = xs[i], y = ys[i], t = times[i];
        int inside = isfinite(x) && isfinite(y) && inside_map(w, x, y);
        int64_t row = 0, col = 0;
        double offset = 0.0;
        if (inside && !world_cell(w, x, y, &row, &col, &offset)) {
            *reason = CHECK_PYTHON;
            break;
        }
        distance += py_hypot(x - last_x, y - last_y);
        last_x = x;
        last_y = y;
        if (!(isfinite(x) && isfinite(y))) {
            *reason = CHECK_COLLISION;
            break;
        }
        double margin = min_clearance + m->radius;
        double drift = m->speed != 0.0 ? m->speed * (t - anchor_t) : 0.0;
        if (anchor_bound - py_hypot(x - anchor_x, y - anchor_y) - drift < margin) {
            double bound = 0.0;
            if (inside) {
                double edge = py_min(py_min(py_min(x - w->x_min, w->x_max - x), y - w->y_min), w->y_max - y);
                bound = py_min(m->centre_field[row * w->cols + col] - offset - sqrt(2.0) * half, edge);
                for (int64_t c = 0; c < w->n_circles; c++) {
                    const double *circle = w->circles + 3 * c;
                    bound = py_min(bound, py_hypot(x - circle[0], y - circle[1]) - circle[2]);
                }
                for (int64_t c = 0; c < m->n_bounds; c++) {
                    const double *circle = m->bounds + 3 * c;
                    bound = py_min(bound, py_hypot(x - circle[0], y - circle[1]) - circle[2]);
                }
                bound = py_max(0.0, bound);
            }
            anchor_x = x;
            anchor_y = y;
            anchor_t = t;
            anchor_bound = bound;
            if (bound < margin) {
                double exact = 0.0;
                if (inside) {
                    query.x = x;
                    query.y = y;
                    query.row = row;
                    query.col = col;
                    query.offset = offset;
                    query.field = m->centre_field[row * w->cols + col];
                    exact = world_distance(&query);
                }
                anchor_bound = exact;
                double clearance = exact - m->radius;
                if (clearance < min_clearance)
                    min_clearance = clearance;
                if (clearance < 0.0) {
                    *reason = CHECK_COLLISION;
                    break;
                }
            }
        }
        if (py_hypot(x - m->goal_x, y - m->goal_y) <= m->tolerance) {
            *reason = CHECK_GOAL;
            break;
        }
    }
    m->last_x = last_x;
    m->last_y = last_y;
    m->distance = distance;
    m->min_clearance = min_clearance;
    m->anchor_x = anchor_x;
    m->anchor_y = anchor_y;
    m->anchor_t = anchor_t;
    m->anchor_bound = anchor_bound;
    return i;
}

/* ---------------------------------------------------------------------------- lidar (lidar.py) */

typedef struct {
    const uint8_t *occupied_up; /* rows x cols, row 0 at the bottom (y grows with the row) */
    int64_t rows, cols;
    double origin_x, origin_y, resolution;
    double range_min, range_max;
    const double *beam_angles; /* count nominal angles [rad] in the sensor frame */
    int64_t count;
    const double *angle_jitter, *range_jitter; /* count each; zeros without noise */
    const double *circles;                     /* n_circles x 3: cx, cy, r */
    int64_t n_circles;
    const double *segments; /* n_segments x 4: ax, ay, bx, by (polygon edges) */
    int64_t n_segments;
    const double *vertices; /* polygon p is vertices[starts[p]:starts[p + 1]] */
    const int64_t *starts;
    int64_t n_starts;
    double *directions; /* count x 2 scratch */
    double *ranges;     /* the output, >= count */
    /* rows x cols as occupied_up: the Chebyshev distance (cells) from each cell to the nearest
     * occupied one, at most 255 (`lidar_clearance`); 0 marks an occupied cell. */
    const uint8_t *clearance;
} Lidar;

/* `Lidar.clearance` of an occupancy grid (rows x cols, nonzero occupied): two passes of the
 * chamfer with the eight neighbours at distance 1, the exact Chebyshev distance to the nearest
 * occupied cell of the grid (cells outside it are free), at most 255. */
void lidar_clearance(const uint8_t *occupied, int64_t rows, int64_t cols, uint8_t *out)
{
    for (int64_t r = 0; r < rows; r++)
        for (int64_t c = 0; c < cols; c++) {
            int64_t d = occupied[r * cols + c] ? 0 : 255;
            if (d && r > 0) {
                for (int64_t k = c - 1; k <= c + 1; k++)
                    if (0 <= k && k < cols)
                        d = int_min(d, (int64_t)out[(r - 1) * cols + k] + 1);
            }
            if (d && c > 0)
                d = int_min(d, (int64_t)out[r * cols + c - 1] + 1);
            out[r * cols + c] = (uint8_t)d;
        }
    for (int64_t r = rows - 1; r >= 0; r--)
        for (int64_t c = cols - 1; c >= 0; c--) {
            int64_t d = out[r * cols + c];
            if (d && r < rows - 1) {
                for (int64_t k = c - 1; k <= c + 1; k++)
                    if (0 <= k && k < cols)
                        d = int_min(d, (int64_t)out[(r + 1) * cols + k] + 1);
            }
            if (d && c < cols - 1)
                d = int_min(d, (int64_t)out[r * cols + c + 1] + 1);
            out[r * cols + c] = (uint8_t)d;
        }
}

/* Lower `out` to the distance [m] to the first occupied cell along each direction, where that is
 * nearer (`out` unchanged when none lies within max_range). Amanatides-Woo traversal: the ray
 * visits cells in order, always crossing the nearer of the next vertical or horizontal cell
 * boundary. A cell is entered at `travelled` (cell units), never less than the cells before it,
 * so the traversal stops once travelled * resolution exceeds out[beam] (the shapes' nearest hit):
 * an occupied cell from there on would not lower it. The bound in cell units is taken a few ulp
 * high (1e-12 relative), so a cell entered at or below out[beam] is still visited.
 *
 * Free space is crossed in strides: from a cell entered at `travelled` whose clearance is c >= 6,
 * the ray's points up to L = (c - 2.01) / max(|dx|, |dy|) further lie within c - 1 cells
 * (Chebyshev) of it, all free, so the traversal moves straight on to its state at travelled + L:
 * every x step below that distance, then every y step, with the additions of the cell-by-cell loop
 * in its order. The loop takes x when next_x < next_y, else y: the x steps X_0 < X_1 < ... and
 * the y steps Y_0 < Y_1 < ... merged in order (a y first on a tie), so it passes through the state
 * with i x steps and j y steps taken exactly when X_{i-1} < Y_j and Y_{j-1} <= X_i; with i, j the
 * counts of steps below s, X_{i-1} < s <= Y_j and Y_{j-1} < s <= X_i. From there the loop goes on
 * as before: the distances it reports are the cell-by-cell loop's. */
static void cast_grid(const Lidar *s, double x, double y, const double *directions, int64_t n, double max_range,
                      double *out)
{
    int64_t rows = s->rows, cols = s->cols;
    double resolution = s->resolution;
    double gx = (x - s->origin_x) / resolution;
    double gy = (y - s->origin_y) / resolution;
    double range_limit = max_range / resolution;
    int64_t start_x = (int64_t)floor(gx);
    int64_t start_y = (int64_t)floor(gy);
    const uint8_t *clearance = s->clearance;
    for (int64_t beam = 0; beam < n; beam++) {
        double dx = directions[2 * beam], dy = directions[2 * beam + 1];
        double bound = out[beam] / resolution * (1.0 + 1e-12);
        double limit = bound < range_limit ? bound : range_limit;
        int64_t ix = start_x, iy = start_y;
        int64_t step_x = dx > 0 ? 1 : -1;
        int64_t step_y = dy > 0 ? 1 : -1;
        double next_x = dx > 0 ? ((double)(ix + 1) - gx) / dx : (dx < 0 ? (gx - (double)ix) / -dx : INFINITY);
        double next_y = dy > 0 ? ((double)(iy + 1) - gy) / dy : (dy < 0 ? (gy - (double)iy) / -dy : INFINITY);
        double delta_x = dx != 0 ? 1.0 / fabs(dx) : INFINITY;
        double delta_y = dy != 0 ? 1.0 / fabs(dy) : INFINITY;
        double stride = 1.0 / py_max(fabs(dx), fabs(dy)); /* distance per cell of Chebyshev offset */
        double travelled = 0.0;
        while (travelled <= limit) {
            if (0 <= ix && ix < cols && 0 <= iy && iy < rows) {
                int64_t c = clearance[iy * cols + ix];
                if (!c) {
                    out[beam] = py_min(travelled * resolution, out[beam]);
                    break;
                }
                if (c >= 6) {
                    double target = travelled + ((double)c - 2.01) * stride;
                    while (next_x < target) {
                        next_x += delta_x;
                        ix += step_x;
                    }
                    while (next_y < target) {
                        next_y += delta_y;
                        iy += step_y;
                    }
                    /* Then one step as below from the cell reached, free (a stride shorter than the
                     * cell leaves it where it was): `travelled` is that step's. */
                }
            } else if ((ix < 0 && step_x < 0) || (ix >= cols && step_x > 0)) {
                break; /* left the grid for good in x */
            } else if ((iy < 0 && step_y < 0) || (iy >= rows && step_y > 0)) {
                break;
            }
            if (next_x < next_y) {
                travelled = next_x;
                next_x += delta_x;
                ix += step_x;
            } else {
                travelled = next_y;
                next_y += delta_y;
                iy += step_y;
            }
        }
    }
}

/* Lower `out` to the nearest hit [m] with the circles and polygon edges along each unit
 * direction; 0 when the sensor is inside a circle or a tangent ray starts on its outline.
 * A circle whose outline lies entirely farther than `cull` [m] from the sensor is skipped (the
 * scan passes its range_max: any hit on such a circle is beyond the range, a missed reading
 * whatever else the beam meets; `lidar_measure` passes infinity). The circles are the outer loop so
 * that the test runs once a circle (a fleet's other robots are mostly out of range); each beam
 * still meets its circles in their order, then the segments, as before. */
static void cast_shapes(const Lidar *s, double x, double y, const double *directions, int64_t n, double *out,
                        double cull)
{
    double reach = cull + 1e-9 * (1.0 + cull); /* a margin for the rounding of near vs hypot - r */
    for (int64_t index = 0; index < s->n_circles; index++) {
        const double *circle = s->circles + 3 * index;
        double offset_x = x - circle[0];
        double offset_y = y - circle[1];
        if (!(hypot(offset_x, offset_y) - circle[2] <= reach))
            continue; /* (also a NaN circle, no robot: every test below would fail for it) */
        double c = offset_x * offset_x + offset_y * offset_y - circle[2] * circle[2];
        for (int64_t beam = 0; beam < n; beam++) {
            double dx = directions[2 * beam], dy = directions[2 * beam + 1];
            double b = dx * offset_x + dy * offset_y;
            if (c <= 0) {
                out[beam] = 0.0;
                continue;
            }
            double discriminant = b * b - c;
            if (discriminant < 0)
                continue;
            double root = sqrt(discriminant);
            double near = -b - root, far = -b + root;
            if (near >= 0)
                out[beam] = py_min(out[beam], near);
            else if (far >= 0)
                out[beam] = 0.0;
        }
    }
    for (int64_t beam = 0; beam < n; beam++) {
        double dx = directions[2 * beam], dy = directions[2 * beam + 1];
        double best = out[beam];
        for (int64_t index = 0; index < s->n_segments; index++) {
            const double *segment = s->segments + 4 * index;
            double ax = segment[0] - x;
            double ay = segment[1] - y;
            double ex = segment[2] - segment[0];
            double ey = segment[3] - segment[1];
            /* Solve t d = a + u e  ->  cross products (2-D determinant of [d, -e]). */
            double denominator = dx * ey - dy * ex;
            if (denominator == 0)
                continue;
            double t = (ax * ey - ay * ex) / denominator;
            double u = (ax * dy - ay * dx) / denominator;
            if (t >= 0 && u >= 0 && u <= 1)
                best = py_min(best, t);
        }
        out[beam] = best;
    }
}

/* True when (x, y) is inside one of the polygons. */
static int inside_polygons(const Lidar *s, double x, double y)
{
    for (int64_t polygon = 0; polygon < s->n_starts - 1; polygon++)
        if (inside_polygon(x, y, s->vertices, s->starts[polygon], s->starts[polygon + 1]))
            return 1;
    return 0;
}

/* `Lidar.measure`: true distances [m] along n unit directions (n x 2, world frame) into `out`;
 * inf for no hit within range_max, all 0 inside a polygon. */
void lidar_measure(const Lidar *s, double x, double y, const double *directions, int64_t n, double *out)
{
    for (int64_t beam = 0; beam < n; beam++)
        out[beam] = INFINITY;
    cast_shapes(s, x, y, directions, n, out, INFINITY);
    cast_grid(s, x, y, directions, n, s->range_max, out);
    if (inside_polygons(s, x, y))
        for (int64_t beam = 0; beam < n; beam++)
            out[beam] = 0.0;
}

/* One sweep into `ranges` (NaN for missed beams): cast directions from the nominal angles plus
 * theta plus the angle jitter, true distances, then the range limits, then the range jitter
 * added to the hits. */
void lidar_scan(const Lidar *s, double x, double y, double theta)
{
    int64_t count = s->count;
    double *directions = s->directions, *ranges = s->ranges;
    for (int64_t beam = 0; beam < count; beam++) {
        double cast = s->beam_angles[beam] + theta + s->angle_jitter[beam];
        directions[2 * beam] = cos(cast);
        directions[2 * beam + 1] = sin(cast);
    }
    for (int64_t beam = 0; beam < count; beam++)
        ranges[beam] = INFINITY;
    cast_shapes(s, x, y, directions, count, ranges, s->range_max);
    cast_grid(s, x, y, directions, count, s->range_max, ranges);
    int inside = inside_polygons(s, x, y);
    for (int64_t beam = 0; beam < count; beam++) {
        double distance = inside ? 0.0 : ranges[beam];
        if (distance < s->range_min || distance > s->range_max || !isfinite(distance))
            ranges[beam] = NAN;
        else
            ranges[beam] = distance + s->range_jitter[beam];
    }
}

/* ------------------------------------------------------------- fleet contacts (fleet.py) */

/* `FleetContacts.steps`'s gaps: robots at positions[k] (steps + 1 rows of n x 2) before step k and
 * positions[k + 1] after it; for each step k and pair p (robots first[p], second[p]) the least gap
 * [m] over the step, gap[k * pairs + p] (the distance at the closest approach of the linearly
 * moving offset minus reach[p]), and the gap at the step's end, end_gap[k * pairs + p]. The
 * operations of the NumPy description it replaced, in its order, element by element: the offsets
 * b - a, w = d1 - d0, s* = -(d0.w) / (w.w) where w.w > 0 (else 0) clipped to [0, 1], then
 * hypot(d0 + s* w) - reach (hypot: NumPy's is the C library's).
 *
 * Both are +inf instead for a pair that is certainly farther apart during the step than
 * floor[a] and floor[b] and 0 (the callers' minimum clearances: such a gap changes neither, nor
 * any contact): on each axis the offset stays at least the smaller of its magnitudes at the ends
 * when it keeps its sign, and the distance is at least the larger axis's bound (taken 1e-12
 * relative low, far more than the rounding). */
/* The gap over the step and at its end of the robots a and b moving from before to after (the
 * rows of `fleet_gaps`), +inf both when certainly farther apart than floor_a, floor_b and 0. */
static inline void pair_gaps(const double *before, const double *after, int64_t a, int64_t b, double reach,
                             double floor_a, double floor_b, double *gap, double *end_gap)
{
    double d0x = before[2 * b] - before[2 * a], d0y = before[2 * b + 1] - before[2 * a + 1];
    double d1x = after[2 * b] - after[2 * a], d1y = after[2 * b + 1] - after[2 * a + 1];
    double low_x = d0x * d1x > 0.0 ? py_min(fabs(d0x), fabs(d1x)) : 0.0;
    double low_y = d0y * d1y > 0.0 ? py_min(fabs(d0y), fabs(d1y)) : 0.0;
    double low = py_max(low_x, low_y) * (1.0 - 1e-12) - reach;
    if (low > 0.0 && low > floor_a && low > floor_b) {
        *gap = INFINITY;
        *end_gap = INFINITY;
        return;
    }
    double wx = d1x - d0x, wy = d1y - d0y;
    double ww = wx * wx + wy * wy;
    double dw = d0x * wx + d0y * wy;
    double s_star = 0.0;
    if (ww > 0.0)
        s_star = -dw / ww;
    if (s_star < 0.0)
        s_star = 0.0;
    else if (s_star > 1.0)
        s_star = 1.0;
    *gap = hypot(d0x + s_star * wx, d0y + s_star * wy) - reach;
    *end_gap = hypot(d1x, d1y) - reach;
}

void fleet_gaps(const double *positions, int64_t steps, int64_t n, const int64_t *first, const int64_t *second,
                int64_t pairs, const double *reach, const double *floor_, double *gap, double *end_gap)
{
    for (int64_t k = 0; k < steps; k++) {
        const double *before = positions + 2 * n * k, *after = positions + 2 * n * (k + 1);
        for (int64_t p = 0; p < pairs; p++) {
            int64_t a = first[p], b = second[p];
            pair_gaps(before, after, a, b, reach[p], floor_[a], floor_[b], &gap[k * pairs + p],
                      &end_gap[k * pairs + p]);
        }
    }
}

/* NumPy's minimum: NaN when either is. */
static inline double nan_min(double a, double b)
{
    return isnan(a) || isnan(b) ? NAN : (b < a ? b : a);
}

/* `FleetContacts.steps` of fleet.py, the NumPy steps it replaced in one pass: `fleet_gaps` of the
 * steps (floors: the minimum clearances at the call), each pair's least gap into both robots'
 * min_clearance (NumPy's minimum), and the steps in which a contact began -- a gap <= 0 while the
 * pair was not touching (touching[p], 0 or 1, updated to whether its gap at each step's end is
 * <= 0) -- into began, (step, pair) in NumPy's nonzero order (by step, then pair). `floor_` is
 * scratch of n. Returns how many began (at most steps x pairs). */
int64_t fleet_contacts(const double *positions, int64_t steps, int64_t n, const int64_t *first,
                       const int64_t *second, int64_t pairs, const double *reach, double *min_clearance,
                       double *floor_, uint8_t *touching, int64_t *began)
{
    int64_t count = 0;
    for (int64_t r = 0; r < n; r++)
        floor_[r] = min_clearance[r];
    for (int64_t k = 0; k < steps; k++) {
        const double *before = positions + 2 * n * k, *after = positions + 2 * n * (k + 1);
        for (int64_t p = 0; p < pairs; p++) {
            int64_t a = first[p], b = second[p];
            double gap, end_gap;
            pair_gaps(before, after, a, b, reach[p], floor_[a], floor_[b], &gap, &end_gap);
            min_clearance[a] = nan_min(min_clearance[a], gap);
            min_clearance[b] = nan_min(min_clearance[b], gap);
            if (gap <= 0.0 && !touching[p]) {
                began[2 * count] = k;
                began[2 * count + 1] = p;
                count++;
            }
            touching[p] = end_gap <= 0.0;
        }
    }
    return count;
}

/* ------------------------------------------------------- judging a fleet's robots (fleet.py) */

/* One robot of `fleet_judge`: its position checks, the numbers of its outcome and of its deadlock
 * rule that a block's steps change (kept here from block to block while it is judged here), and
 * what ended its judging in the last block. */
typedef struct {
    Monitor *monitor; /* its `world_check_positions` (points for at least a block's steps) */
    int64_t active;   /* judged by `fleet_judge` (else left alone) */
    double last_x, last_y;                          /* out: the position after the last step judged */
    double distance, recovery_time, stopped_time;   /* its RobotOutcome's, added to */
    double deadlocked_at;                           /* its RobotOutcome's (NaN: None) */
    double best, best_time, progress_deadlocked_at; /* its Progress (NaN: None) */
    double deadlock_after, goal_x, goal_y;          /* the Progress's setting; the current goal */
    double time;                                    /* its monitor's outcome time: the last step checked */
    double stopped_speed, progress, recover;        /* fleet.py's STOPPED_SPEED, PROGRESS, MODE_RECOVER */
    double moved;          /* out: the distance moved in the step of the event */
    int64_t event, reason; /* out: that step (n: none) and why (CHECK_*) */
} Judge;

/* `_judge_block` of fleet.py for each active robot r of the block's n steps (starts robots x 2:
 * the positions before the first step; positions n x robots x 2 after each step, modes n x robots
 * the avoidance mode held in it, ends and lengths [s] of the steps), up to the step in which it
 * reached its goal or collided, or the step its checks leave to Python (CHECK_PYTHON: nothing of
 * that step taken into account), the same operations in the same order (Python's hypot): the
 * positions checked in one `world_check_positions` call, then per step the distance moved, the
 * recovery time, the stopped time and the deadlock rule (`Progress.update`; in the step of an
 * event its distance and recovery time only). A robot that ends so is no longer active; its index
 * goes to `ended`. Returns how many did. Its monitor must not read a moving world. */
int64_t fleet_judge(Judge *judges, int64_t robots, const double *starts, const double *positions,
                    const double *modes, const double *ends, const double *lengths, int64_t n, int64_t *ended)
{
    int64_t count = 0;
    for (int64_t r = 0; r < robots; r++) {
        Judge *j = judges + r;
        if (!j->active)
            continue;
        Monitor *m = j->monitor;
        if (n > m->capacity || n < 1) {
            j->last_x = starts[2 * r];
            j->last_y = starts[2 * r + 1];
            j->event = 0;
            j->reason = CHECK_PYTHON;
            j->active = 0;
            ended[count++] = r;
            continue;
        }
        double *xs = (double *)m->points, *ys = xs + m->capacity, *times = ys + m->capacity;
        for (int64_t k = 0; k < n; k++) {
            xs[k] = positions[2 * (k * robots + r)];
            ys[k] = positions[2 * (k * robots + r) + 1];
            times[k] = ends[k];
        }
        int64_t event = world_check_positions(m, n);
        int64_t reason = m->reason;
        int64_t stop = reason == CHECK_PYTHON ? event : (event < n ? event + 1 : n);
        double bx = starts[2 * r], by = starts[2 * r + 1], moved = 0.0;
        double distance = j->distance, recovery = j->recovery_time, stopped = j->stopped_time;
        double dead = j->deadlocked_at, best = j->best, best_time = j->best_time;
        double progress_dead = j->progress_deadlocked_at;
        for (int64_t k = 0; k < stop; k++) {
            double x = xs[k], y = ys[k], h = lengths[k];
            moved = py_hypot(x - bx, y - by);
            bx = x;
            by = y;
            distance += moved;
            if (modes[k * robots + r] == j->recover)
                recovery += h;
            if (k == event)
                break;
            if (moved < j->stopped_speed * h)
                stopped += h;
            double remaining = py_hypot(j->goal_x - x, j->goal_y - y), t = ends[k];
            if (remaining < best - j->progress) {
                best = remaining;
                best_time = t;
                progress_dead = NAN;
            } else if (isnan(progress_dead) && t - best_time >= j->deadlock_after - 1e-9) {
                progress_dead = best_time;
            }
            dead = progress_dead;
        }
        j->last_x = bx;
        j->last_y = by;
        j->distance = distance;
        j->recovery_time = recovery;
        j->stopped_time = stopped;
        j->deadlocked_at = dead;
        j->best = best;
        j->best_time = best_time;
        j->progress_deadlocked_at = progress_dead;
        j->moved = moved;
        j->event = event;
        j->reason = reason;
        if (reason == CHECK_GOING) {
            j->time = times[n - 1];
        } else {
            j->active = 0;
            ended[count++] = r;
        }
    }
    return count;
}

/* ------------------------------------ a fleet's Python components in one call a block (fleet.py) */

/* One copy of a gather: `count` values into consecutive inputs from outputs `stride` values apart,
 * each the connection's value: the output times `scale` when `multiply`, plus `offset` when `add`
 * (the operations of fast_loop.py's `transfer_expression`, without its no-op terms). */
typedef struct {
    const double *source;
    double *target;
    int64_t count, stride;
    int64_t multiply, add;
    double scale, offset;
} BlockCopy;

/* One Python component of `_PythonSteps` (fleet.py), in the master's order, or the copies into
 * the components that read them (BLOCK_COPIES, last): due at step k when k % period == 0, its
 * inputs gathered by copies[first_copy .. first_copy + copies), then stepped by its kind. */
typedef struct {
    int64_t period;
    int64_t kind; /* BLOCK_* */
    int64_t first_copy, copies;
    const Lidar *lidar;      /* BLOCK_LIDAR: its sweep's struct */
    const double *inputs;    /* BLOCK_LIDAR: its inputs x, y, theta, robots_x[j], robots_y[j] */
    double *robot_rows;      /* BLOCK_LIDAR: the other robots' circles (robots rows cx, cy, r) */
    int64_t robots;
    int64_t (*c_step)(void *, double); /* BLOCK_C_STEP: its C step (nonzero: Python goes on) */
    void *state;
} BlockStep;

enum { BLOCK_PYTHON = 0, BLOCK_LIDAR = 1, BLOCK_C_STEP = 2, BLOCK_COPIES = 3 };

/* One due component's gather, then its lidar sweep or C step; nonzero when its C step hands it to
 * Python. */
static int64_t block_step(const BlockStep *s, const BlockCopy *copies, double t)
{
    for (int64_t c = s->first_copy; c < s->first_copy + s->copies; c++) {
        const BlockCopy *copy = copies + c;
        const double *source = copy->source;
        double *target = copy->target;
        int64_t stride = copy->stride;
        if (!copy->multiply && !copy->add) {
            for (int64_t j = 0; j < copy->count; j++)
                target[j] = source[j * stride];
        } else {
            for (int64_t j = 0; j < copy->count; j++) {
                double value = source[j * stride];
                if (copy->multiply)
                    value = value * copy->scale;
                if (copy->add)
                    value = value + copy->offset;
                target[j] = value;
            }
        }
    }
    if (s->kind == BLOCK_LIDAR) {
        const double *in = s->inputs;
        for (int64_t j = 0; j < s->robots; j++) {
            s->robot_rows[3 * j] = in[3 + j];
            s->robot_rows[3 * j + 1] = in[3 + s->robots + j];
        }
        lidar_scan(s->lidar, in[0], in[1], in[2]);
    } else if (s->kind == BLOCK_C_STEP) {
        return s->c_step(s->state, t) != 0;
    }
    return 0;
}

/* The steps of `n` components due at step k (time t [s]) from `start` on: for each, its gather,
 * then a lidar's step (`Lidar.step`: the other robots' circles at the positions on its inputs, a
 * sweep from the pose on them) or a C step (`PlannerComponent.kernel_step`). Returns the first
 * component Python must step (BLOCK_PYTHON: nothing of it done; BLOCK_C_STEP: gathered, its C step
 * handed over), or n when all are done. */
int64_t fleet_python_block(const BlockStep *steps, int64_t n, int64_t start, int64_t k, double t,
                           const BlockCopy *copies)
{
    for (int64_t i = start; i < n; i++) {
        const BlockStep *s = steps + i;
        if (k % s->period)
            continue;
        if (s->kind == BLOCK_PYTHON)
            return i;
        if (block_step(s, copies, t))
            return i;
    }
    return n;
}


/* ------------------------------- the same on the machine's cores (a fleet's robots side by side) */

/* Within one step k the due components fall into chains (`_BlockProgram.make`): a chain's
 * components read (through their gathers) only outputs of the FMUs, which no step of this call
 * writes, and of components of the same chain; each writes only its own inputs, outputs and state
 * (a lidar's circles, scratch and ranges; a planner's costmap, its scratch and step state); the
 * maps they share are read-only. So the chains may step side by side, each in the master's order on
 * one thread, up to its first component handed to Python. The hand-backs are returned one at a
 * time in the master's order, and a chain goes on after Python has stepped the one it handed back.
 * No two chains touch the same memory: each component's operations, and so its results, are those
 * of `fleet_python_block`, bit for bit. A component stepped by Python only (BLOCK_PYTHON) may read
 * anything: the chains before it are done before it is handed back, those after it start after. */

typedef struct BlockPool BlockPool;

/* `_BlockProgram`'s steps in chains, and the stretch of a step under way. */
typedef struct {
    const BlockStep *steps; /* n entries: the components in the master's order, the feeds last */
    int64_t n;
    const BlockCopy *copies;
    const int64_t *members; /* the chained entries (neither BLOCK_PYTHON nor the feeds), chain by chain */
    const int64_t *firsts;  /* chains + 1: chain c is members[firsts[c] .. firsts[c + 1]), in order */
    int64_t chains;
    int64_t *cursor;        /* chains, scratch: where each chain stopped (a hand-back, or `end`) */
    int64_t *due;           /* chains, scratch: the chains with a component due in the stretch */
    BlockPool *pool;        /* NULL: one thread */
    int64_t min_chains;     /* fewer chains due in a stretch: all stepped on the calling thread */
    /* The stretch under way (`open`): step k at t, the components up to `end` (a BLOCK_PYTHON
     * component due, or the feeds), the chains from `start` on. */
    int64_t open, k, start, end;
    double t;
} BlockProgram;

/* Chain c's due components from `from` up to the stretch's end: the first handed to Python, or
 * the end. */
static int64_t block_chain(const BlockProgram *p, int64_t c, int64_t from)
{
    for (int64_t m = p->firsts[c]; m < p->firsts[c + 1]; m++) {
        int64_t i = p->members[m];
        if (i < from)
            continue;
        if (i >= p->end)
            break;
        const BlockStep *s = p->steps + i;
        if (p->k % s->period)
            continue;
        if (block_step(s, p->copies, p->t))
            return i;
    }
    return p->end;
}

/* A call of the master's stepping kernel (`navcosim_step_kernel` of cosim/core/native/kernel.c,
 * reached through its address) on one set of its tables: `block_pool_kernels` runs a fleet's
 * kernel split by robots (fleet.py's `_SplitKernel`) on the pool's threads. */
typedef int64_t (*KernelCall)(int64_t, int64_t, int64_t, int64_t, int64_t, int64_t, const void *, int64_t *);
typedef struct {
    KernelCall function;
    int64_t first_step, steps, start_ns, h_ns;
    const void *tables;
    int64_t *result;
} KernelJob;

/* Worker threads (the calling thread is one more): a job is a program's due chains of a stretch,
 * each taken by whichever thread is free, or kernel calls (`kernels`, each taken so). Every field
 * is read and written under `lock`. */
struct BlockPool {
    pthread_mutex_t lock;
    pthread_cond_t wake, finished;
    pthread_t *threads;
    int64_t count;      /* the workers started */
    int64_t generation; /* counts the jobs: a worker sleeps until it changes, or `stop` */
    int stop;
    BlockProgram *job;
    KernelJob *kernels; /* a job of kernel calls (`block_pool_kernels`) instead of chains */
    int64_t due_count, front, back, done; /* the job's chains p->due[0 .. due_count): those left, done */
    pid_t pid;                      /* the process of the threads (a forked child has none) */
    int64_t away_from;              /* Linux: the CPU the workers are kept off (-1: none) */
};

/* Step the job's chains left, the calling thread from the first on, the workers from the last back
 * (each robot's memory mostly stays in one CPU's cache from step to step); called with the lock
 * held, returns with it held. */
/* One kernel call of `block_pool_kernels`. */
static void run_kernel_job(const KernelJob *call)
{
    call->function(call->first_step, call->steps, 0, call->start_ns, call->h_ns, 0, call->tables, call->result);
}

static void block_pool_take(BlockPool *pool, int caller)
{
    BlockProgram *p = pool->job;
    while (pool->front < pool->back) {
        int64_t task = caller ? pool->front++ : --pool->back;
        KernelJob *kernels = pool->kernels;
        pthread_mutex_unlock(&pool->lock);
        if (kernels)
            run_kernel_job(kernels + task);
        else
            p->cursor[p->due[task]] = block_chain(p, p->due[task], p->start);
        pthread_mutex_lock(&pool->lock);
        if (++pool->done == pool->due_count)
            pthread_cond_signal(&pool->finished);
    }
}

static void *block_worker(void *argument)
{
    BlockPool *pool = argument;
    pthread_mutex_lock(&pool->lock);
    int64_t seen = pool->generation;
    for (;;) {
        while (pool->generation == seen && !pool->stop)
            pthread_cond_wait(&pool->wake, &pool->lock);
        if (pool->stop)
            break;
        seen = pool->generation;
        block_pool_take(pool, 0);
    }
    pthread_mutex_unlock(&pool->lock);
    return NULL;
}

void block_pool_free(BlockPool *pool);

/* A pool of `workers` threads; NULL when none could be started. */
BlockPool *block_pool_new(int64_t workers)
{
    if (workers < 1)
        return NULL;
    BlockPool *pool = calloc(1, sizeof(BlockPool));
    if (!pool)
        return NULL;
    pool->threads = calloc((size_t)workers, sizeof(pthread_t));
    if (!pool->threads) {
        free(pool);
        return NULL;
    }
    pthread_mutex_init(&pool->lock, NULL);
    pthread_cond_init(&pool->wake, NULL);
    pthread_cond_init(&pool->finished, NULL);
    pool->pid = getpid();
    pool->away_from = -1;
    for (int64_t w = 0; w < workers; w++) {
        if (pthread_create(pool->threads + w, NULL, block_worker, pool) != 0)
            break;
        pool->count++;
    }
    if (!pool->count) {
        block_pool_free(pool);
        return NULL;
    }
    return pool;
}

/* Stops and joins the pool's threads (none in a forked child: only its memory is freed). */
void block_pool_free(BlockPool *pool)
{
    if (!pool)
        return;
    if (pool->pid == getpid()) {
        pthread_mutex_lock(&pool->lock);
        pool->stop = 1;
        pthread_cond_broadcast(&pool->wake);
        pthread_mutex_unlock(&pool->lock);
        for (int64_t w = 0; w < pool->count; w++)
            pthread_join(pool->threads[w], NULL);
        pthread_mutex_destroy(&pool->lock);
        pthread_cond_destroy(&pool->wake);
        pthread_cond_destroy(&pool->finished);
    }
    free(pool->threads);
    free(pool);
}

/* The workers kept off the calling thread's CPU: woken where it runs they would wait for it (the
 * scheduler places a woken thread beside its waker when no CPU is idle). */
static void block_pool_place(BlockPool *pool)
{
#ifdef __linux__
    int cpu = sched_getcpu();
    if (cpu >= 0 && cpu != pool->away_from) {
        cpu_set_t allowed;
        if (sched_getaffinity(0, sizeof allowed, &allowed) == 0 && CPU_COUNT(&allowed) > 1) {
            CPU_CLR(cpu, &allowed);
            for (int64_t w = 0; w < pool->count; w++)
                pthread_setaffinity_np(pool->threads[w], sizeof allowed, &allowed);
        }
        pool->away_from = cpu;
    }
#else
    (void)pool;
#endif
}

/* The pool's `n` tasks (the due chains of `job`, or the kernel calls `kernels`) on its workers and
 * this thread, returning once all are done. */
static void block_pool_run(BlockPool *pool, BlockProgram *job, KernelJob *kernels, int64_t n)
{
    block_pool_place(pool);
    pthread_mutex_lock(&pool->lock);
    pool->job = job;
    pool->kernels = kernels;
    pool->due_count = n;
    pool->front = pool->done = 0;
    pool->back = n;
    pool->generation++;
    pthread_cond_broadcast(&pool->wake);
    block_pool_take(pool, 1);
    while (pool->done < pool->due_count)
        pthread_cond_wait(&pool->finished, &pool->lock);
    pool->job = NULL;
    pool->kernels = NULL;
    pthread_mutex_unlock(&pool->lock);
}

/* The `n` kernel calls side by side, this thread taking them from the first on, the pool's workers
 * from the last back (all on this thread without a pool of this process); each call's result in
 * its own `result`. The calls must touch disjoint memory (tables, buffers, FMU instances). */
void block_pool_kernels(BlockPool *pool, KernelJob *calls, int64_t n)
{
    if (!pool || n < 2 || pool->pid != getpid()) {
        for (int64_t j = 0; j < n; j++)
            run_kernel_job(calls + j);
        return;
    }
    block_pool_run(pool, NULL, calls, n);
}

/* The chains of the stretch from p->start: the due ones on the pool's threads and this one (on this
 * one alone with fewer than p->min_chains, or no pool of this process), each to its first
 * hand-back. */
static void block_stretch(BlockProgram *p)
{
    int64_t due = 0;
    for (int64_t c = 0; c < p->chains; c++) {
        p->cursor[c] = p->end;
        for (int64_t m = p->firsts[c]; m < p->firsts[c + 1]; m++) {
            int64_t i = p->members[m];
            if (i >= p->start && i < p->end && !(p->k % p->steps[i].period)) {
                p->due[due++] = c;
                break;
            }
        }
    }
    BlockPool *pool = p->pool;
    if (!pool || due < p->min_chains || due < 2 || pool->pid != getpid()) {
        for (int64_t d = 0; d < due; d++)
            p->cursor[p->due[d]] = block_chain(p, p->due[d], p->start);
        return;
    }
    block_pool_run(pool, p, NULL, due);
}

/* The first chain's stop before the stretch's end (the next hand-back, in the master's order), or
 * the end. */
static int64_t block_next_hand_back(const BlockProgram *p)
{
    int64_t first = p->end;
    for (int64_t c = 0; c < p->chains; c++)
        if (p->cursor[c] < first)
            first = p->cursor[c];
    return first;
}

/* `fleet_python_block` for the program `p`, its chains side by side: the same returns (the index of
 * the next component Python must step, or n), the same calls from Python (`start` 0, then the
 * index after each returned). A chain that handed back the component before `start` goes on from
 * `start` (on this thread); the others' cursors stand. */
int64_t fleet_python_block_threads(BlockProgram *p, int64_t start, int64_t k, double t)
{
    int64_t n = p->n;
    if (start == 0 || p->k != k || p->t != t)
        p->open = 0;
    if (p->open) {
        for (int64_t c = 0; c < p->chains; c++)
            if (p->cursor[c] == start - 1)
                p->cursor[c] = block_chain(p, c, start);
    }
    for (;;) {
        if (p->open) {
            int64_t next = block_next_hand_back(p);
            if (next < p->end)
                return next;
            p->open = 0;
            start = p->end;
            if (start >= n - 1)
                break;
            return start; /* (a BLOCK_PYTHON component due: its index) */
        }
        int64_t end = start;
        while (end < n - 1 && !(p->steps[end].kind == BLOCK_PYTHON && !(k % p->steps[end].period)))
            end++;
        p->k = k;
        p->t = t;
        p->start = start;
        p->end = end;
        p->open = 1;
        block_stretch(p);
    }
    /* The feeds (the last entry, never handed back). */
    if (start < n && !(k % p->steps[n - 1].period))
        block_step(p->steps + n - 1, p->copies, t);
    return n;
}

/* The tables Python mirrors (see layout.h). */
int64_t navcosim_layout(const char **names, int64_t *values, int64_t capacity)
{
    int64_t n = 0;
    LAYOUT_SIZE(World);
    LAYOUT_FIELD(World, occupied);
    LAYOUT_FIELD(World, rows);
    LAYOUT_FIELD(World, cols);
    LAYOUT_FIELD(World, x_min);
    LAYOUT_FIELD(World, y_min);
    LAYOUT_FIELD(World, x_max);
    LAYOUT_FIELD(World, y_max);
    LAYOUT_FIELD(World, resolution);
    LAYOUT_FIELD(World, circles);
    LAYOUT_FIELD(World, n_circles);
    LAYOUT_FIELD(World, vertices);
    LAYOUT_FIELD(World, starts);
    LAYOUT_FIELD(World, n_starts);
    LAYOUT_FIELD(World, x);
    LAYOUT_FIELD(World, y);
    LAYOUT_FIELD(World, row);
    LAYOUT_FIELD(World, col);
    LAYOUT_FIELD(World, offset);
    LAYOUT_FIELD(World, field);
    LAYOUT_SIZE(Monitor);
    LAYOUT_FIELD(Monitor, world);
    LAYOUT_FIELD(Monitor, centre_field);
    LAYOUT_FIELD(Monitor, bounds);
    LAYOUT_FIELD(Monitor, n_bounds);
    LAYOUT_FIELD(Monitor, radius);
    LAYOUT_FIELD(Monitor, goal_x);
    LAYOUT_FIELD(Monitor, goal_y);
    LAYOUT_FIELD(Monitor, tolerance);
    LAYOUT_FIELD(Monitor, speed);
    LAYOUT_FIELD(Monitor, last_x);
    LAYOUT_FIELD(Monitor, last_y);
    LAYOUT_FIELD(Monitor, distance);
    LAYOUT_FIELD(Monitor, min_clearance);
    LAYOUT_FIELD(Monitor, anchor_x);
    LAYOUT_FIELD(Monitor, anchor_y);
    LAYOUT_FIELD(Monitor, anchor_t);
    LAYOUT_FIELD(Monitor, anchor_bound);
    LAYOUT_FIELD(Monitor, reason);
    LAYOUT_FIELD(Monitor, points);
    LAYOUT_FIELD(Monitor, capacity);
    LAYOUT_SIZE(Judge);
    LAYOUT_FIELD(Judge, monitor);
    LAYOUT_FIELD(Judge, active);
    LAYOUT_FIELD(Judge, last_x);
    LAYOUT_FIELD(Judge, last_y);
    LAYOUT_FIELD(Judge, distance);
    LAYOUT_FIELD(Judge, recovery_time);
    LAYOUT_FIELD(Judge, stopped_time);
    LAYOUT_FIELD(Judge, deadlocked_at);
    LAYOUT_FIELD(Judge, best);
    LAYOUT_FIELD(Judge, best_time);
    LAYOUT_FIELD(Judge, progress_deadlocked_at);
    LAYOUT_FIELD(Judge, deadlock_after);
    LAYOUT_FIELD(Judge, goal_x);
    LAYOUT_FIELD(Judge, goal_y);
    LAYOUT_FIELD(Judge, time);
    LAYOUT_FIELD(Judge, stopped_speed);
    LAYOUT_FIELD(Judge, progress);
    LAYOUT_FIELD(Judge, recover);
    LAYOUT_FIELD(Judge, moved);
    LAYOUT_FIELD(Judge, event);
    LAYOUT_FIELD(Judge, reason);
    LAYOUT_SIZE(Lidar);
    LAYOUT_FIELD(Lidar, occupied_up);
    LAYOUT_FIELD(Lidar, rows);
    LAYOUT_FIELD(Lidar, cols);
    LAYOUT_FIELD(Lidar, origin_x);
    LAYOUT_FIELD(Lidar, origin_y);
    LAYOUT_FIELD(Lidar, resolution);
    LAYOUT_FIELD(Lidar, range_min);
    LAYOUT_FIELD(Lidar, range_max);
    LAYOUT_FIELD(Lidar, beam_angles);
    LAYOUT_FIELD(Lidar, count);
    LAYOUT_FIELD(Lidar, angle_jitter);
    LAYOUT_FIELD(Lidar, range_jitter);
    LAYOUT_FIELD(Lidar, circles);
    LAYOUT_FIELD(Lidar, n_circles);
    LAYOUT_FIELD(Lidar, segments);
    LAYOUT_FIELD(Lidar, n_segments);
    LAYOUT_FIELD(Lidar, vertices);
    LAYOUT_FIELD(Lidar, starts);
    LAYOUT_FIELD(Lidar, n_starts);
    LAYOUT_FIELD(Lidar, directions);
    LAYOUT_FIELD(Lidar, ranges);
    LAYOUT_FIELD(Lidar, clearance);
    LAYOUT_SIZE(BlockCopy);
    LAYOUT_FIELD(BlockCopy, source);
    LAYOUT_FIELD(BlockCopy, target);
    LAYOUT_FIELD(BlockCopy, count);
    LAYOUT_FIELD(BlockCopy, stride);
    LAYOUT_FIELD(BlockCopy, multiply);
    LAYOUT_FIELD(BlockCopy, add);
    LAYOUT_FIELD(BlockCopy, scale);
    LAYOUT_FIELD(BlockCopy, offset);
    LAYOUT_SIZE(BlockStep);
    LAYOUT_FIELD(BlockStep, period);
    LAYOUT_FIELD(BlockStep, kind);
    LAYOUT_FIELD(BlockStep, first_copy);
    LAYOUT_FIELD(BlockStep, copies);
    LAYOUT_FIELD(BlockStep, lidar);
    LAYOUT_FIELD(BlockStep, inputs);
    LAYOUT_FIELD(BlockStep, robot_rows);
    LAYOUT_FIELD(BlockStep, robots);
    LAYOUT_FIELD(BlockStep, c_step);
    LAYOUT_FIELD(BlockStep, state);
    LAYOUT_SIZE(BlockProgram);
    LAYOUT_FIELD(BlockProgram, steps);
    LAYOUT_FIELD(BlockProgram, n);
    LAYOUT_FIELD(BlockProgram, copies);
    LAYOUT_FIELD(BlockProgram, members);
    LAYOUT_FIELD(BlockProgram, firsts);
    LAYOUT_FIELD(BlockProgram, chains);
    LAYOUT_FIELD(BlockProgram, cursor);
    LAYOUT_FIELD(BlockProgram, due);
    LAYOUT_FIELD(BlockProgram, pool);
    LAYOUT_FIELD(BlockProgram, min_chains);
    LAYOUT_FIELD(BlockProgram, open);
    LAYOUT_FIELD(BlockProgram, k);
    LAYOUT_FIELD(BlockProgram, start);
    LAYOUT_FIELD(BlockProgram, end);
    LAYOUT_FIELD(BlockProgram, t);
    LAYOUT_CONSTANT(BLOCK_PYTHON);
    LAYOUT_CONSTANT(BLOCK_LIDAR);
    LAYOUT_CONSTANT(BLOCK_C_STEP);
    LAYOUT_CONSTANT(BLOCK_COPIES);
    return n;
}
