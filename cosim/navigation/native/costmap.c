/* Kernels of cosim.navigation.costmap: one lidar scan into the marks, and "a new mark near the plan?".
 *
 * Built by native/load.py (C99, -ffp-contract=off, no fast-math): every floating-point
 * operation is the one of the Python description, in the same order, so the results are those of
 * the numba kernels these replaced, bit for bit. The long-lived arrays and constants come in one
 * struct set up once by `Costmap` (its `ctypes.Structure` mirrors it field for field). */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "../../world/native/geometry.h" /* py_min, int_min, int_max */
#include "../../../planner/native/layout.h"

typedef struct {
    uint8_t *marked;       /* rows x cols, row 0 at the top (the grid's convention) */
    const uint8_t *known;  /* rows x cols: known occupied cells, never cleared */
    int64_t rows, cols;
    double origin_x, origin_y, resolution;
    const double *angles;  /* count beam angles [rad] in the sensor frame */
    int64_t count;
    const double *ranges;  /* count ranges [m] of the scan (NaN: no return) */
    double clear_to;       /* how far a beam without a return clears [m] (0: not at all) */
    int64_t *row_marks;    /* rows: marked cells in each row (kept by the kernel, with `marked`) */
    int64_t *col_marks;    /* cols: marked cells in each column */
    const double *cos_angles, *sin_angles; /* count: cos and sin of the beam angles, to a few ulp */
    /* Beams evenly spread round the full turn (`uniform` 1): angles[k] = first_angle + k step to
     * 1e-9 rad, step = 2 pi / count. Then each scan finds the beams near each mark (`near_*`). */
    int64_t uniform;
    double first_angle, step;
    double *near_from, *near_to; /* count each, scratch: where a beam's marks may lie (cell units) */
    int64_t *near_cell;          /* count, scratch: the one mark near the beam, -1 none, -2 several */
} Costmap;

/* Limits of the approximate direction's use (see costmap_integrate_scan): angles [rad], distances
 * (cell units), the point's coordinates (cell units), and the slack of the approximate mark. */
#define FAST_ANGLE 1e3
#define FAST_LIMIT 1e4
#define FAST_COORDINATE 1e6
#define MARK_SLACK 1e-7


/* floor(v) for |v| < 2^52 without a call to libm (C99's floor is one on baseline x86-64). */
static inline double floor_near(double v)
{
    double truncated = (double)(int64_t)v;
    return truncated > v ? truncated - 1.0 : truncated;
}

/* Narrow [*t_lo, *t_hi] to where g + t d lies within [low, high] on one axis; 0 when a ray parallel
 * to the axis (d == 0) lies outside. */
static inline int clip_to_slab(double g, double d, double low, double high, double *t_lo, double *t_hi)
{
    if (d != 0) {
        double inverse = 1.0 / d;
        double a = (low - g) * inverse, b = (high - g) * inverse;
        if (a > b) {
            double swap = a;
            a = b;
            b = swap;
        }
        if (a > *t_lo)
            *t_lo = a;
        if (b < *t_hi)
            *t_hi = b;
        return 1;
    }
    return !(g < low || g > high);
}

/* Can the ray from (gx, gy) along (dx, dy), up to `limit` (cell units), come within a cell of the
 * box [x_lo, x_hi] x [y_lo, y_hi] of cells? A clip of the segment against the box grown by one
 * cell on every side: the traversal's cells all touch the segment (its rounding errors are many
 * orders of magnitude below a cell), so a "no" means the ray visits no cell of the box. */
static int ray_near_box(double gx, double gy, double dx, double dy, double limit, int64_t x_lo, int64_t x_hi,
                        int64_t y_lo, int64_t y_hi)
{
    double t_lo = 0.0, t_hi = limit;
    if (!clip_to_slab(gx, dx, (double)x_lo - 1.0, (double)x_hi + 2.0, &t_lo, &t_hi))
        return 0;
    if (!clip_to_slab(gy, dy, (double)y_lo - 1.0, (double)y_hi + 2.0, &t_lo, &t_hi))
        return 0;
    return t_lo <= t_hi;
}

/* The traversal of costmap_integrate_scan moved on to its state at distance s (cell units), from a
 * state whose steps were all taken below s: every x step below s, then every y step below s, each
 * with the loop's own additions in its order. The loop takes x when next_x < next_y, else y: it
 * takes the x steps X_0 < X_1 < ... and the y steps Y_0 < Y_1 < ... merged in order (a y first on
 * a tie), so it passes through the state with i x steps and j y steps taken exactly when
 * X_{i-1} < Y_j and Y_{j-1} <= X_i; with i, j the counts of steps below s, X_{i-1} < s <= Y_j and
 * Y_{j-1} < s <= X_i. The cells it leaves before s are skipped. */
static inline void skip_to(double s, double *next_x, double *next_y, int64_t *ix, int64_t *iy, double delta_x,
                           double delta_y, int64_t step_x, int64_t step_y)
{
    double x = *next_x, y = *next_y;
    int64_t cx = *ix, cy = *iy;
    while (x < s) {
        x += delta_x;
        cx += step_x;
    }
    while (y < s) {
        y += delta_y;
        cy += step_y;
    }
    *next_x = x;
    *next_y = y;
    *ix = cx;
    *iy = cy;
}

/* Note the mark at cell (cx, cy) (traversal units) for the beams that may touch it, for a scan from
 * (gx, gy) (cell units) at heading theta, with evenly spread beams (`Costmap.uniform`). A ray that
 * touches the cell points between the directions of its corners (seen from outside the cell, they
 * span less than a half turn) and touches it at distances from the cell's nearest point to its
 * farthest corner. The beams whose angles lie in that span, widened by 1e-8 rad (the beams' angles
 * are within 1e-9 rad of the even spread; theta + angle and atan2 round far less), get the
 * distances in `near_from` (less 1e-6) and `near_to`; every beam when the sensor is within
 * 1e-3 cells of the cell. */
#define HALF_TURN 3.14159265358979323846
static void note_mark(const Costmap *m, double gx, double gy, double theta, int64_t cx, int64_t cy)
{
    double x0 = (double)cx - gx, y0 = (double)cy - gy; /* the cell's lower left corner */
    double nearest_x = x0 > 0.0 ? x0 : (x0 + 1.0 < 0.0 ? x0 + 1.0 : 0.0);
    double nearest_y = y0 > 0.0 ? y0 : (y0 + 1.0 < 0.0 ? y0 + 1.0 : 0.0);
    double near = hypot(nearest_x, nearest_y);
    /* The farthest corner: on each axis the end farther from the sensor (equal ends: either). */
    double far = hypot(x0 + 0.5 < 0.0 ? x0 : x0 + 1.0, y0 + 0.5 < 0.0 ? y0 : y0 + 1.0);
    int64_t count = m->count, lo = 0, hi = count - 1;
    double corners[4][2] = {{x0, y0}, {x0 + 1.0, y0}, {x0, y0 + 1.0}, {x0 + 1.0, y0 + 1.0}};
    if (near > 1e-3) {
        /* The corners span less than a half turn, so one lies clockwise of another exactly when
         * their cross product is negative: the most clockwise and counter-clockwise corners are
         * found so, and only their directions taken (to rounding, which the window's 1e-8 rad
         * covers many times over, the least and greatest of the four). */
        int first = 0, last = 0;
        for (int corner = 1; corner < 4; corner++) {
            const double *c = corners[corner], *a = corners[first], *b = corners[last];
            if (a[0] * c[1] - a[1] * c[0] < 0.0)
                first = corner;
            if (b[0] * c[1] - b[1] * c[0] > 0.0)
                last = corner;
        }
        double centre = atan2(y0 + 0.5, x0 + 0.5), low = 0.0, high = 0.0;
        for (int end = 0; end < 2; end++) {
            const double *corner = corners[end ? last : first];
            double turn = atan2(corner[1], corner[0]) - centre;
            turn += turn > HALF_TURN ? -2.0 * HALF_TURN : (turn < -HALF_TURN ? 2.0 * HALF_TURN : 0.0);
            low = py_min(low, turn);
            high = py_max(high, turn);
        }
        double base = centre - theta - m->first_angle;
        lo = (int64_t)ceil((base + low - 1e-8) / m->step);
        hi = (int64_t)floor((base + high + 1e-8) / m->step);
        if (hi - lo >= count) {
            lo = 0;
            hi = count - 1;
        }
    }
    int64_t cell = (m->rows - 1 - cy) * m->cols + cx;
    for (int64_t k = lo; k <= hi; k++) {
        int64_t beam = k % count;
        beam += beam < 0 ? count : 0;
        m->near_from[beam] = py_min(m->near_from[beam], near - 1e-6);
        m->near_to[beam] = py_max(m->near_to[beam], far);
        m->near_cell[beam] = m->near_cell[beam] == -1 ? cell : -2;
    }
}

/* Mark each return's cell and clear the marked cells before it (see costmap.py's docstring), for
 * the scan in `ranges` taken at pose (x, y, theta). Returns the number of changed cells.
 *
 * Only marked cells can be cleared, so a beam is traversed only where it may meet one. A pose that
 * is not finite (or absurdly far, 1e15 cells) changes nothing.
 *
 * The exact direction (cos and sin of theta + angle, as the Python kernel had them) costs most of
 * a beam that is not traversed. So a beam first takes an approximate direction from the angle sum
 * formula: it differs from the exact one by less than 2e-12 (theta and angle within FAST_ANGLE),
 * so less than 1e-7 cells at the end of a ray of FAST_LIMIT cells. Where the marks may lie:
 * - beams evenly spread round the full turn (`uniform`, a 360-degree lidar): the beams that may
 *   touch each mark, and at what distances, are found once a scan from the mark (`note_mark`;
 *   the marks set during the scan are noted as they are set). A beam meets no mark when none lies
 *   nearer than its limit; else it is traversed only over the distances where its marks lie
 *   (`skip_to` to the first, stopping past the last); a beam whose one mark is its return's own
 *   cell, already marked, changes nothing (the traversal stops before the return's cell);
 * - other beams: a beam that passes a cell or more from the box of the marks meets none.
 * A beam that meets no mark and whose return's cell is certain (its approximate mark point is
 * more than MARK_SLACK from a cell boundary; the exact point lies 1e-6 cells past the surface) and
 * outside the grid, known or already marked changes nothing. Every other beam takes the exact
 * direction and the exact path below. */
int64_t costmap_integrate_scan(const Costmap *m, double x, double y, double theta)
{
    int64_t rows = m->rows, cols = m->cols;
    uint8_t *marked = m->marked;
    const uint8_t *known = m->known;
    int64_t *row_marks = m->row_marks, *col_marks = m->col_marks;
    double resolution = m->resolution;
    double gx = (x - m->origin_x) / resolution;
    double gy = (y - m->origin_y) / resolution;
    int64_t changed = 0;
    if (!(fabs(gx) < 1e15 && fabs(gy) < 1e15))
        return 0;
    /* The box of the marked cells in traversal units (ix = column, iy = rows - 1 - row); empty
     * when x_lo > x_hi. */
    int64_t x_lo = 0, x_hi = -1, y_lo = 0, y_hi = -1;
    for (int64_t c = 0; c < cols; c++)
        if (col_marks[c]) {
            x_lo = c;
            break;
        }
    for (int64_t c = cols - 1; c >= 0; c--)
        if (col_marks[c]) {
            x_hi = c;
            break;
        }
    for (int64_t r = rows - 1; r >= 0; r--)
        if (row_marks[r]) {
            y_lo = rows - 1 - r;
            break;
        }
    for (int64_t r = 0; r < rows; r++)
        if (row_marks[r]) {
            y_hi = rows - 1 - r;
            break;
        }
    int fast = fabs(theta) <= FAST_ANGLE && fabs(gx) <= FAST_COORDINATE && fabs(gy) <= FAST_COORDINATE;
    double cos_theta = fast ? cos(theta) : 0.0, sin_theta = fast ? sin(theta) : 0.0;
    int by_marks = fast && m->uniform; /* the beams near each mark, found once a scan */
    if (by_marks) {
        for (int64_t beam = 0; beam < m->count; beam++) {
            m->near_from[beam] = INFINITY;
            m->near_to[beam] = -INFINITY;
            m->near_cell[beam] = -1;
        }
        for (int64_t r = 0; x_lo <= x_hi && r < rows; r++)
            if (row_marks[r])
                for (int64_t c = x_lo; c <= x_hi; c++)
                    if (marked[r * cols + c])
                        note_mark(m, gx, gy, theta, c, rows - 1 - r);
    }
    for (int64_t beam = 0; beam < m->count; beam++) {
        double distance = m->ranges[beam];
        int hit = isfinite(distance);
        if (!hit) {
            distance = m->clear_to;
            if (distance <= 0.0)
                continue;
        }
        double limit = distance / resolution;
        /* The marked cells the ray may visit lie within [from, to] along it (cell units). */
        double from = -INFINITY, to = INFINITY;
        int may_clear = 1;
        if (fast && fabs(m->angles[beam]) <= FAST_ANGLE && limit <= FAST_LIMIT) {
            double ca = m->cos_angles[beam], sa = m->sin_angles[beam];
            double ax = cos_theta * ca - sin_theta * sa, ay = sin_theta * ca + cos_theta * sa;
            int near;
            if (by_marks) {
                /* The traversal looks at cells it enters before `limit`, and a mark lies no nearer
                 * than near_from along the ray. */
                near = m->near_from[beam] < limit;
                from = m->near_from[beam] - 1.0;
                to = m->near_to[beam] + 1.0;
            } else {
                near = x_lo <= x_hi && ray_near_box(gx, gy, ax, ay, limit, x_lo, x_hi, y_lo, y_hi);
            }
            /* Where the approximate mark point certainly lies (-1: not certain or outside the grid). */
            int64_t certain = -1, outside = 0;
            if (hit && (!near || m->near_cell[beam] >= 0)) {
                double px = gx + ax * (limit + 1e-6), py = gy + ay * (limit + 1e-6);
                double cx = floor_near(px - MARK_SLACK), cy = floor_near(py - MARK_SLACK);
                if (cx == floor_near(px + MARK_SLACK) && cy == floor_near(py + MARK_SLACK)) {
                    if (cx >= 0 && cx < (double)cols && cy >= 0 && cy < (double)rows)
                        certain = (rows - 1 - (int64_t)cy) * cols + (int64_t)cx;
                    else
                        outside = 1;
                }
            }
            if (!near) {
                if (!hit || outside || (certain >= 0 && (marked[certain] || known[certain])))
                    continue; /* clears nothing, marks nothing */
                may_clear = 0;
            } else if (by_marks && certain >= 0 && certain == m->near_cell[beam] && marked[certain]) {
                continue; /* the only mark near the ray is its return's own cell: never cleared, marked */
            }
        }
        double dx = cos(theta + m->angles[beam]);
        double dy = sin(theta + m->angles[beam]);
        /* Cells the ray crosses before reaching `distance` (Amanatides-Woo, in cell units). */
        int64_t ix = (int64_t)floor(gx), iy = (int64_t)floor(gy);
        int64_t step_x = dx > 0 ? 1 : -1;
        int64_t step_y = dy > 0 ? 1 : -1;
        double next_x = dx > 0 ? ((double)(ix + 1) - gx) / dx : (dx < 0 ? (gx - (double)ix) / -dx : INFINITY);
        double next_y = dy > 0 ? ((double)(iy + 1) - gy) / dy : (dy < 0 ? (gy - (double)iy) / -dy : INFINITY);
        double delta_x = dx != 0 ? 1.0 / fabs(dx) : INFINITY;
        double delta_y = dy != 0 ? 1.0 / fabs(dy) : INFINITY;
        int traverse = may_clear && x_lo <= x_hi && ray_near_box(gx, gy, dx, dy, limit, x_lo, x_hi, y_lo, y_hi);
        if (traverse && from > 0.0)
            skip_to(py_min(from, limit), &next_x, &next_y, &ix, &iy, delta_x, delta_y, step_x, step_y);
        while (traverse) {
            double leaving = py_min(next_x, next_y); /* where the ray leaves cell (ix, iy) */
            if (hit && leaving >= limit)
                break; /* the return's own cell */
            if (0 <= ix && ix < cols && 0 <= iy && iy < rows) {
                int64_t cell = (rows - 1 - iy) * cols + ix;
                if (marked[cell] && !known[cell]) {
                    marked[cell] = 0;
                    row_marks[rows - 1 - iy]--;
                    col_marks[ix]--;
                    changed++;
                }
            }
            if (leaving >= limit || leaving >= to)
                break; /* (past `to`: the cells further on are unmarked) */
            if (next_x < next_y) {
                next_x += delta_x;
                ix += step_x;
            } else {
                next_y += delta_y;
                iy += step_y;
            }
        }
        if (hit) {
            /* Just past the surface, so a return on a cell boundary marks the cell behind it. */
            double px = gx + dx * (limit + 1e-6);
            double py = gy + dy * (limit + 1e-6);
            /* 0 <= floor(p) < n exactly when 0 <= p < n (n an integer): no cast of a far point. */
            if (px >= 0 && px < (double)cols && py >= 0 && py < (double)rows) {
                int64_t cx = (int64_t)floor(px), cy = (int64_t)floor(py);
                int64_t cell = (rows - 1 - cy) * cols + cx;
                if (!marked[cell] && !known[cell]) {
                    marked[cell] = 1;
                    row_marks[rows - 1 - cy]++;
                    col_marks[cx]++;
                    if (x_lo > x_hi) {
                        x_lo = x_hi = cx;
                        y_lo = y_hi = cy;
                    } else {
                        x_lo = int_min(x_lo, cx);
                        x_hi = int_max(x_hi, cx);
                        y_lo = int_min(y_lo, cy);
                        y_hi = int_max(y_hi, cy);
                    }
                    if (by_marks)
                        note_mark(m, gx, gy, theta, cx, cy);
                    changed++;
                }
            }
        }
    }
    return changed;
}

/* True when a cell marked now but not in `since` (rows x cols) has its centre within `radius` [m]
 * of one of the n points (n x 2). */
int costmap_new_marks_near(const Costmap *m, const uint8_t *since, const double *points, int64_t n, double radius)
{
    int64_t rows = m->rows, cols = m->cols;
    double resolution = m->resolution, origin_x = m->origin_x, origin_y = m->origin_y;
    int64_t reach = (int64_t)ceil(radius / resolution) + 1;
    for (int64_t index = 0; index < n; index++) {
        double px = points[2 * index], py = points[2 * index + 1];
        int64_t col = (int64_t)floor((px - origin_x) / resolution);
        int64_t iy = (int64_t)floor((py - origin_y) / resolution);
        int64_t cy_stop = int_min(iy + reach + 1, rows), cx_stop = int_min(col + reach + 1, cols);
        for (int64_t cy = int_max(iy - reach, 0); cy < cy_stop; cy++) {
            int64_t row = rows - 1 - cy;
            double centre_y = origin_y + ((double)cy + 0.5) * resolution;
            for (int64_t cx = int_max(col - reach, 0); cx < cx_stop; cx++) {
                int64_t cell = row * cols + cx;
                if (m->marked[cell] && !since[cell]) {
                    double centre_x = origin_x + ((double)cx + 0.5) * resolution;
                    if (hypot(centre_x - px, centre_y - py) <= radius)
                        return 1;
                }
            }
        }
    }
    return 0;
}

/* Can `costmap_new_marks_near` find a new mark (marked now, not in `since`) near the points of the
 * plan (points n x 2, arc n: arc length [m] at each point) interpolated at arc lengths from `low`
 * to `high` [m], given that each such point lies on a segment between two of the plan's points
 * whose arc lengths bracket it? 0 when certainly not: no new mark in the window that search
 * examines round any point of the bounding box of those plan points (widened by 1e-9 relative,
 * far more than the interpolation's rounding); 1 when it may. `first`: a point whose arc length is
 * at most `low` (the planner's current segment). */
int costmap_new_marks_maybe_near(const Costmap *m, const uint8_t *since, const double *points, const double *arc,
                                 int64_t n, int64_t first, double low, double high, double radius)
{
    if (n <= 0 || first < 0 || first >= n || !(low >= arc[first]))
        return 1;
    while (first + 1 < n && arc[first + 1] <= low)
        first++;
    int64_t last = first;
    while (last + 1 < n && !(arc[last] >= high))
        last++;
    double x_min = INFINITY, x_max = -INFINITY, y_min = INFINITY, y_max = -INFINITY;
    for (int64_t k = first; k <= last; k++) {
        x_min = py_min(x_min, points[2 * k]);
        x_max = py_max(x_max, points[2 * k]);
        y_min = py_min(y_min, points[2 * k + 1]);
        y_max = py_max(y_max, points[2 * k + 1]);
    }
    if (!(isfinite(x_min) && isfinite(x_max) && isfinite(y_min) && isfinite(y_max)))
        return 1;
    x_min -= 1e-9 * (1.0 + fabs(x_min));
    x_max += 1e-9 * (1.0 + fabs(x_max));
    y_min -= 1e-9 * (1.0 + fabs(y_min));
    y_max += 1e-9 * (1.0 + fabs(y_max));
    int64_t rows = m->rows, cols = m->cols;
    double resolution = m->resolution;
    int64_t reach = (int64_t)ceil(radius / resolution) + 1; /* as costmap_new_marks_near */
    double lo_x = floor((x_min - m->origin_x) / resolution), hi_x = floor((x_max - m->origin_x) / resolution);
    double lo_y = floor((y_min - m->origin_y) / resolution), hi_y = floor((y_max - m->origin_y) / resolution);
    if (!(fabs(lo_x) < 1e15 && fabs(hi_x) < 1e15 && fabs(lo_y) < 1e15 && fabs(hi_y) < 1e15))
        return 1;
    int64_t cx_lo = int_max((int64_t)lo_x - reach, 0), cx_stop = int_min((int64_t)hi_x + reach + 1, cols);
    int64_t cy_lo = int_max((int64_t)lo_y - reach, 0), cy_stop = int_min((int64_t)hi_y + reach + 1, rows);
    for (int64_t cy = cy_lo; cy < cy_stop; cy++) {
        int64_t row = rows - 1 - cy;
        for (int64_t cx = cx_lo; cx < cx_stop; cx++)
            if (m->marked[row * cols + cx] && !since[row * cols + cx])
                return 1;
    }
    return 0;
}

/* The distance (cell units) from every cell to the nearest known or marked cell into out (rows x
 * cols), given known_d2, the squared distances to the nearest known cell (integers, exact), and
 * reach >= every finite one's square root: a mark can be the nearest only to cells less than that
 * far from it, so each mark lowers the squared distances in the square of cells `reach` round it;
 * then the square roots. Integers throughout, so the values are those of the exact transform of
 * the known and marked cells (planner/native/distance.c) bit for bit. */
void costmap_distance(const Costmap *m, const double *known_d2, int64_t reach, double *out)
{
    int64_t rows = m->rows, cols = m->cols;
    for (int64_t cell = 0; cell < rows * cols; cell++)
        out[cell] = known_d2[cell];
    for (int64_t r = 0; r < rows; r++) {
        if (!m->row_marks[r])
            continue;
        for (int64_t c = 0; c < cols; c++) {
            if (!m->marked[r * cols + c])
                continue;
            int64_t r_stop = int_min(r + reach + 1, rows), c_stop = int_min(c + reach + 1, cols);
            for (int64_t q = int_max(r - reach, 0); q < r_stop; q++) {
                double dr = (double)(q - r);
                double *line = out + q * cols;
                for (int64_t p = int_max(c - reach, 0); p < c_stop; p++) {
                    double dc = (double)(p - c);
                    double d2 = dr * dr + dc * dc;
                    if (d2 < line[p])
                        line[p] = d2;
                }
            }
        }
    }
    for (int64_t cell = 0; cell < rows * cols; cell++)
        out[cell] = sqrt(out[cell]);
}

/* The planner's progress along its plan (`PlannerComponent._advance_progress`): of the segments
 * points[first..stop] (points n x 2, segment j from point j to j + 1), the one whose closest point
 * is nearest to (x, y), the first of equals. Its index goes to *segment; returns the progress [m]
 * there: arc[j] + fraction * |segment j|. A zero-length segment's fraction is 0; a fraction is
 * clipped to [0, 1]. Operations in the order of the NumPy description it replaced. */
double path_progress(const double *points, const double *arc, int64_t first, int64_t stop, double x,
                     double y, int64_t *segment)
{
    int64_t best = first;
    double best_distance = INFINITY, best_fraction = 0.0, best_length_sq = 0.0;
    for (int64_t j = first; j < stop; j++) {
        double ax = points[2 * j], ay = points[2 * j + 1];
        double ex = points[2 * j + 2] - ax, ey = points[2 * j + 3] - ay;
        double length_sq = ex * ex + ey * ey;
        double fraction = ((x - ax) * ex + (y - ay) * ey) / length_sq;
        if (fraction != fraction)
            fraction = 0.0; /* 0 / 0 */
        else
            fraction = fraction < 0.0 ? 0.0 : (fraction > 1.0 ? 1.0 : fraction);
        double distance = hypot(ax + fraction * ex - x, ay + fraction * ey - y);
        if (j == first || !(distance >= best_distance)) { /* nearer, or NaN */
            best = j;
            best_distance = distance;
            best_fraction = fraction;
            best_length_sq = length_sq;
            if (distance != distance)
                break; /* NaN: NumPy's argmin takes the first */
        }
    }
    *segment = best;
    return arc[best] + best_fraction * sqrt(best_length_sq);
}

/* ---- The replanning planner's step in C (`cosim.navigation.planner.PlannerComponent`) ----------
 * What `PlannerComponent.step` does at a step that needs no Python, for the master's compiled
 * kernel (a Python component's C step, `kernel_step`): the scan into the costmap, the progress
 * along the plan, the replan triggers (the look for new marks near the plan ahead too,
 * `planner_look_ahead`); the same operations in the same order. It returns 1 without finishing,
 * `pending` set, where Python must go on: PENDING_MARKS, a new mark may lie near the plan ahead and
 * the look needs more points than the scratch holds (Python makes the points and looks: the rest
 * of `_trigger`), PENDING_REPLAN, a trigger fired (`reason`) and the interval allows a replan. The state is the component's own (its
 * attributes read and write these fields), so its Python step and this one go on from each other. */
typedef struct {
    const Costmap *costmap;
    double *scan;                 /* the costmap's scan buffer (costmap->count ranges) */
    const double *inputs;         /* the component's inputs: x, y, theta, steering_dir, ranges */
    const double *points;         /* the plan: waypoint_count x 2 [m] */
    const double *arc;            /* its arc lengths [m] */
    int64_t waypoint_count;
    const uint8_t *marks_at_plan; /* the costmap's marks when the plan was made */
    double replan_after, replan_stall_time, replan_horizon, replan_interval; /* [s], [s], [m], [s] */
    double vehicle_radius, spacing, stall_distance; /* [m]; spacing: of the points ahead */
    int64_t resolves_obstacles, search_window;
    int64_t active;               /* 0: the step does nothing (no replanning, or no path) */
    int64_t following;            /* waypoints given from outside: the costmap only */
    int64_t segment;              /* of the plan, where the progress lies */
    double progress;              /* [m] along the plan */
    double blocked_since;         /* [s] since VFH has no free direction; NaN: it has one */
    double mark_time, mark_progress; /* the last real progress: [s], [m] */
    int64_t obstacle_on_plan;
    double last_replan;           /* [s] */
    int64_t pending, reason;
    /* Scratch of the look for new marks ahead (`planner_look_ahead`): 3 x ahead_capacity values, the arc
     * lengths then the points; a look that needs more is Python's (PENDING_MARKS). */
    double *ahead;
    int64_t ahead_capacity;
} PlannerStep;

enum { PENDING_NONE = 0, PENDING_MARKS = 1, PENDING_REPLAN = 2 };
enum { REASON_NONE = 0, REASON_NO_FREE_DIRECTION = 1, REASON_STALLED = 2, REASON_OBSTACLE_ON_PLAN = 3 };

/* NumPy's interp(x, xp, fp) at one x (not NaN) for xp (n >= 1, non-decreasing) and fp = values[2 k]
 * (a column of an n x 2 array), both ends held: the last k with xp[k] <= x (its binary search),
 * fp there at a knot or the last point, else the slope times the offset plus fp[k], tried from the
 * segment's other end when that is NaN (and fp[k] when both ends are equal). */
static double interp_like_numpy(double x, const double *xp, const double *values, int64_t n)
{
    if (n == 1)
        return values[0];
    if (x > xp[n - 1])
        return values[2 * (n - 1)];
    if (x < xp[0])
        return values[0];
    int64_t low = 0, high = n;
    while (low < high) {
        int64_t mid = low + ((high - low) >> 1);
        if (x >= xp[mid])
            low = mid + 1;
        else
            high = mid;
    }
    int64_t j = low - 1;
    if (j == n - 1 || xp[j] == x)
        return values[2 * j];
    double slope = (values[2 * j + 2] - values[2 * j]) / (xp[j + 1] - xp[j]);
    double value = slope * (x - xp[j]) + values[2 * j];
    if (isnan(value)) {
        value = slope * (x - xp[j + 1]) + values[2 * j + 2];
        if (isnan(value) && values[2 * j] == values[2 * j + 2])
            value = values[2 * j];
    }
    return value;
}

/* `PlannerComponent._look_ahead`: whether a new mark lies near the plan ahead, its points every
 * `spacing` along the plan from the progress to `replan_horizon` further (`_plan_ahead`: NumPy's
 * arange of the arc lengths, its length ceil((stop - start) / step), its values start, start +
 * step, then start + i delta with delta the difference of those two; those up to the plan's end;
 * interp of the points' x and y), then `costmap_new_marks_near`. -1 when the points would not fit
 * the scratch (Python looks). The points are left in the scratch. */
int64_t planner_look_ahead(const PlannerStep *s)
{
    int64_t n = s->waypoint_count;
    const double *arc = s->arc;
    double last = arc[n - 1], start = s->progress, spacing = s->spacing;
    double end = start + s->replan_horizon;
    double stop = py_min(end, last) + spacing;
    double delta = stop - start, quotient = delta / spacing;
    int64_t length;
    if (quotient == 0.0 && delta != 0.0) {
        length = signbit(quotient) ? 0 : 1;
    } else {
        double ceiling = ceil(quotient);
        if (!(ceiling <= (double)s->ahead_capacity))
            return -1;
        length = (int64_t)ceiling;
    }
    if (length <= 0)
        return 0;
    if (length > s->ahead_capacity)
        return -1;
    double *along = s->ahead, *points = s->ahead + s->ahead_capacity;
    along[0] = start;
    if (length > 1) {
        along[1] = start + spacing;
        double step = along[1] - along[0];
        for (int64_t i = 2; i < length; i++)
            along[i] = start + (double)i * step;
    }
    int64_t count = 0;
    for (int64_t i = 0; i < length; i++) {
        if (!(along[i] <= last))
            continue;
        points[2 * count] = interp_like_numpy(along[i], arc, s->points, n);
        points[2 * count + 1] = interp_like_numpy(along[i], arc, s->points + 1, n);
        count++;
    }
    if (count == 0)
        return 0;
    return costmap_new_marks_near(s->costmap, s->marks_at_plan, points, count, s->vehicle_radius) != 0;
}

int64_t planner_step(PlannerStep *s, double t)
{
    if (!s->active)
        return 0;
    const double *in = s->inputs;
    double x = in[0], y = in[1], theta = in[2], steering = in[3];
    if (!(isfinite(x) && isfinite(y) && isfinite(theta)))
        return 0;
    memcpy(s->scan, in + 4, sizeof(double) * (size_t)s->costmap->count);
    int64_t changed = costmap_integrate_scan(s->costmap, x, y, theta);
    if (s->following)
        return 0;
    int64_t first = s->segment;
    int64_t stop = first + s->search_window < s->waypoint_count - 1 ? first + s->search_window
                                                                     : s->waypoint_count - 1;
    if (stop > first) {
        int64_t nearest = first;
        double progress = path_progress(s->points, s->arc, first, stop, x, y, &nearest);
        if (progress > s->progress) {
            s->segment = nearest;
            s->progress = progress;
        }
    }
    int64_t reason = REASON_NONE;
    if (isnan(steering)) {
        if (isnan(s->blocked_since))
            s->blocked_since = t;
        else if (t - s->blocked_since >= s->replan_after)
            reason = REASON_NO_FREE_DIRECTION;
    } else {
        s->blocked_since = NAN;
    }
    if (reason == REASON_NONE) {
        if (s->progress >= s->mark_progress + s->stall_distance) {
            s->mark_time = t;
            s->mark_progress = s->progress;
        } else if (t - s->mark_time >= s->replan_stall_time) {
            reason = REASON_STALLED;
        }
    }
    if (reason == REASON_NONE) {
        if (changed > 0 && !s->obstacle_on_plan && s->resolves_obstacles) {
            double end = s->progress + s->replan_horizon, last = s->arc[s->waypoint_count - 1];
            double high = (last < end ? last : end) + 2.0 * s->spacing;
            if (costmap_new_marks_maybe_near(s->costmap, s->marks_at_plan, s->points, s->arc,
                                             s->waypoint_count, s->segment, s->progress, high,
                                             s->vehicle_radius)) {
                int64_t near = planner_look_ahead(s); /* (`_look_ahead`, its finding the trigger) */
                if (near < 0) {
                    s->pending = PENDING_MARKS;
                    return 1;
                }
                s->obstacle_on_plan = near;
            }
        }
        if (s->obstacle_on_plan)
            reason = REASON_OBSTACLE_ON_PLAN;
    }
    if (reason != REASON_NONE && t - s->last_replan >= s->replan_interval) {
        s->pending = PENDING_REPLAN;
        s->reason = reason;
        return 1;
    }
    return 0;
}

/* The tables Python mirrors (see layout.h). */
int64_t navcosim_layout(const char **names, int64_t *values, int64_t capacity)
{
    int64_t n = 0;
    LAYOUT_SIZE(Costmap);
    LAYOUT_SIZE(PlannerStep);
    LAYOUT_FIELD(PlannerStep, costmap);
    LAYOUT_FIELD(PlannerStep, scan);
    LAYOUT_FIELD(PlannerStep, inputs);
    LAYOUT_FIELD(PlannerStep, points);
    LAYOUT_FIELD(PlannerStep, arc);
    LAYOUT_FIELD(PlannerStep, waypoint_count);
    LAYOUT_FIELD(PlannerStep, marks_at_plan);
    LAYOUT_FIELD(PlannerStep, replan_after);
    LAYOUT_FIELD(PlannerStep, replan_stall_time);
    LAYOUT_FIELD(PlannerStep, replan_horizon);
    LAYOUT_FIELD(PlannerStep, replan_interval);
    LAYOUT_FIELD(PlannerStep, vehicle_radius);
    LAYOUT_FIELD(PlannerStep, spacing);
    LAYOUT_FIELD(PlannerStep, stall_distance);
    LAYOUT_FIELD(PlannerStep, resolves_obstacles);
    LAYOUT_FIELD(PlannerStep, search_window);
    LAYOUT_FIELD(PlannerStep, active);
    LAYOUT_FIELD(PlannerStep, following);
    LAYOUT_FIELD(PlannerStep, segment);
    LAYOUT_FIELD(PlannerStep, progress);
    LAYOUT_FIELD(PlannerStep, blocked_since);
    LAYOUT_FIELD(PlannerStep, mark_time);
    LAYOUT_FIELD(PlannerStep, mark_progress);
    LAYOUT_FIELD(PlannerStep, obstacle_on_plan);
    LAYOUT_FIELD(PlannerStep, last_replan);
    LAYOUT_FIELD(PlannerStep, pending);
    LAYOUT_FIELD(PlannerStep, reason);
    LAYOUT_FIELD(PlannerStep, ahead);
    LAYOUT_FIELD(PlannerStep, ahead_capacity);
    LAYOUT_CONSTANT(PENDING_MARKS);
    LAYOUT_CONSTANT(PENDING_REPLAN);
    LAYOUT_CONSTANT(REASON_NO_FREE_DIRECTION);
    LAYOUT_CONSTANT(REASON_STALLED);
    LAYOUT_CONSTANT(REASON_OBSTACLE_ON_PLAN);
    LAYOUT_FIELD(Costmap, marked);
    LAYOUT_FIELD(Costmap, known);
    LAYOUT_FIELD(Costmap, rows);
    LAYOUT_FIELD(Costmap, cols);
    LAYOUT_FIELD(Costmap, origin_x);
    LAYOUT_FIELD(Costmap, origin_y);
    LAYOUT_FIELD(Costmap, resolution);
    LAYOUT_FIELD(Costmap, angles);
    LAYOUT_FIELD(Costmap, count);
    LAYOUT_FIELD(Costmap, ranges);
    LAYOUT_FIELD(Costmap, clear_to);
    LAYOUT_FIELD(Costmap, row_marks);
    LAYOUT_FIELD(Costmap, col_marks);
    LAYOUT_FIELD(Costmap, cos_angles);
    LAYOUT_FIELD(Costmap, sin_angles);
    LAYOUT_FIELD(Costmap, uniform);
    LAYOUT_FIELD(Costmap, first_angle);
    LAYOUT_FIELD(Costmap, step);
    LAYOUT_FIELD(Costmap, near_from);
    LAYOUT_FIELD(Costmap, near_to);
    LAYOUT_FIELD(Costmap, near_cell);
    return n;
}
