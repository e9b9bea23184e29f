/* Kernels of cosim.world: the exact clearance (distance.py), the lidar's ray casting (lidar.py)
 * and the point-polygon geometry they share (geometry.h, exported for geometry.py). A fleet's
 * kernels (contacts, judging, its Python components in one call a block) are fleet.c's, a library
 * of their own that only a fleet loads.
 *
 * Built by native/load.py (C99, -ffp-contract=off, no fast-math): every floating-point
 * operation is the one the Python docstrings describe, in the same order, so the results are
 * those of the numba kernels these replaced, bit for bit. The long-lived arrays and constants of
 * a lidar or a world come in one struct set up once in Python (the `ctypes.Structure`s of
 * cosim/world/kernels.py mirror them field for field); a call passes its address and the pose. */
#include <math.h>
#include <stdint.h>

#include "geometry.h"
#include "pyhypot.h"
#include "world.h"
#include "../../../planner/native/layout.h"

double world_polygon_distance(double x, double y, const double *vertices, int64_t first, int64_t stop)
{
    return polygon_distance(x, y, vertices, first, stop);
}

/* ---------------------------------------------------------------- exact clearance (distance.py) */

struct World {
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
};

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

struct Lidar {
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
};

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
    LAYOUT_CONSTANT(CHECK_GOING);
    LAYOUT_CONSTANT(CHECK_COLLISION);
    LAYOUT_CONSTANT(CHECK_GOAL);
    LAYOUT_CONSTANT(CHECK_PYTHON);
    return n;
}
