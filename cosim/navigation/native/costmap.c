/* Kernels of cosim.navigation.costmap: one lidar scan into the marks, and "a new mark near the plan?".
 *
 * Built by planner/native.py (C99, -ffp-contract=off, no fast-math): every floating-point
 * operation is the one of the Python description, in the same order, so the results are those of
 * the numba kernels these replaced, bit for bit. The long-lived arrays and constants come in one
 * struct set up once by `Costmap` (its `ctypes.Structure` mirrors it field for field). */
#include <math.h>
#include <stdint.h>

typedef struct {
    uint8_t *marked;       /* rows x cols, row 0 at the top (the grid's convention) */
    const uint8_t *known;  /* rows x cols: known occupied cells, never cleared */
    int64_t rows, cols;
    double origin_x, origin_y, resolution;
    const double *angles;  /* count beam angles [rad] in the sensor frame */
    int64_t count;
    const double *ranges;  /* count ranges [m] of the scan (NaN: no return) */
    double clear_to;       /* how far a beam without a return clears [m] (0: not at all) */
} Costmap;

static inline int64_t int_min(int64_t a, int64_t b) { return b < a ? b : a; }
static inline int64_t int_max(int64_t a, int64_t b) { return b > a ? b : a; }
static inline double py_min(double a, double b) { return b < a ? b : a; }

/* Mark each return's cell and clear the marked cells before it (see costmap.py's docstring), for
 * the scan in `ranges` taken at pose (x, y, theta). Returns the number of changed cells. */
int64_t costmap_integrate_scan(const Costmap *m, double x, double y, double theta)
{
    int64_t rows = m->rows, cols = m->cols;
    uint8_t *marked = m->marked;
    const uint8_t *known = m->known;
    double resolution = m->resolution;
    double gx = (x - m->origin_x) / resolution;
    double gy = (y - m->origin_y) / resolution;
    int64_t changed = 0;
    for (int64_t beam = 0; beam < m->count; beam++) {
        double distance = m->ranges[beam];
        int hit = isfinite(distance);
        if (!hit) {
            distance = m->clear_to;
            if (distance <= 0.0)
                continue;
        }
        double dx = cos(theta + m->angles[beam]);
        double dy = sin(theta + m->angles[beam]);
        /* Cells the ray crosses before reaching `distance` (Amanatides-Woo, in cell units). */
        double limit = distance / resolution;
        int64_t ix = (int64_t)floor(gx), iy = (int64_t)floor(gy);
        int64_t step_x = dx > 0 ? 1 : -1;
        int64_t step_y = dy > 0 ? 1 : -1;
        double next_x = dx > 0 ? ((double)(ix + 1) - gx) / dx : (dx < 0 ? (gx - (double)ix) / -dx : INFINITY);
        double next_y = dy > 0 ? ((double)(iy + 1) - gy) / dy : (dy < 0 ? (gy - (double)iy) / -dy : INFINITY);
        double delta_x = dx != 0 ? 1.0 / fabs(dx) : INFINITY;
        double delta_y = dy != 0 ? 1.0 / fabs(dy) : INFINITY;
        for (;;) {
            double leaving = py_min(next_x, next_y); /* where the ray leaves cell (ix, iy) */
            if (hit && leaving >= limit)
                break; /* the return's own cell */
            if (0 <= ix && ix < cols && 0 <= iy && iy < rows) {
                int64_t cell = (rows - 1 - iy) * cols + ix;
                if (marked[cell] && !known[cell]) {
                    marked[cell] = 0;
                    changed++;
                }
            }
            if (leaving >= limit)
                break;
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
            int64_t cx = (int64_t)floor(px), cy = (int64_t)floor(py);
            if (0 <= cx && cx < cols && 0 <= cy && cy < rows) {
                int64_t cell = (rows - 1 - cy) * cols + cx;
                if (!marked[cell] && !known[cell]) {
                    marked[cell] = 1;
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
