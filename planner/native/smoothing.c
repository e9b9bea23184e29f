/* Line of sight on the padded blocked map (planner.smoothing): the supercover walk of a segment,
 * a polyline made of them, and greedy farthest-visible pruning of a path. Loaded with native.load.
 *
 * Coordinates u, v are in cells: u along the columns, v along the rows pointing down, cell
 * (row, col) = [col, col + 1) x [row, row + 1). Points are n x 2 float64 (u, v) rows.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

enum { BLOCKED = 1 };

static int segment_clear(const uint8_t *blocked, int64_t width, double u0, double v0, double u1, double v1) {
    int64_t col = (int64_t)floor(u0);
    int64_t row = (int64_t)floor(v0);
    int64_t end_col = (int64_t)floor(u1);
    int64_t end_row = (int64_t)floor(v1);
    double du = u1 - u0;
    double dv = v1 - v0;
    int64_t step_col = du > 0 ? 1 : -1;
    int64_t step_row = dv > 0 ? 1 : -1;
    double t_delta_u = du != 0.0 ? fabs(1.0 / du) : INFINITY;
    double t_delta_v = dv != 0.0 ? fabs(1.0 / dv) : INFINITY;
    double t_max_u, t_max_v;
    if (du > 0)
        t_max_u = ((double)(col + 1) - u0) / du;
    else if (du < 0)
        t_max_u = ((double)col - u0) / du;
    else
        t_max_u = INFINITY;
    if (dv > 0)
        t_max_v = ((double)(row + 1) - v0) / dv;
    else if (dv < 0)
        t_max_v = ((double)row - v0) / dv;
    else
        t_max_v = INFINITY;
    int64_t walk = llabs(end_col - col) + llabs(end_row - row) + 2;
    for (int64_t i = 0; i < walk; i++) {
        if (blocked[(row + 1) * width + col + 1] == BLOCKED) return 0;
        if (col == end_col && row == end_row) return 1;
        if (fabs(t_max_u - t_max_v) < 1e-12) {
            /* Through a corner: both side cells count as touched. */
            if (blocked[(row + 1) * width + col + step_col + 1] == BLOCKED) return 0;
            if (blocked[(row + step_row + 1) * width + col + 1] == BLOCKED) return 0;
            col += step_col;
            row += step_row;
            t_max_u += t_delta_u;
            t_max_v += t_delta_v;
        } else if (t_max_u < t_max_v) {
            col += step_col;
            t_max_u += t_delta_u;
        } else {
            row += step_row;
            t_max_v += t_delta_v;
        }
    }
    return 0; /* rounding kept the walk from reaching the end cell: refuse, to stay safe */
}

int64_t navcosim_segment_clear(const uint8_t *blocked, int64_t width, double u0, double v0, double u1, double v1) {
    return segment_clear(blocked, width, u0, v0, u1, v1);
}

int64_t navcosim_polyline_clear(const uint8_t *blocked, int64_t width, const double *points, int64_t count) {
    for (int64_t index = 0; index + 1 < count; index++) {
        const double *p = points + 2 * index;
        if (!segment_clear(blocked, width, p[0], p[1], p[2], p[3])) return 0;
    }
    return 1;
}

/* Indices of the kept waypoints into keep[count]; returns how many. */
int64_t navcosim_prune_line_of_sight(const uint8_t *blocked, int64_t width, const double *points, int64_t count,
                                     int64_t *keep) {
    int64_t kept = 0;
    int64_t anchor = 0;
    keep[kept++] = 0;
    while (anchor < count - 1) {
        int64_t chosen = anchor + 1;
        const double *a = points + 2 * anchor;
        for (int64_t candidate = count - 1; candidate > anchor + 1; candidate--) {
            const double *c = points + 2 * candidate;
            if (segment_clear(blocked, width, a[0], a[1], c[0], c[1])) {
                chosen = candidate;
                break;
            }
        }
        keep[kept++] = chosen;
        anchor = chosen;
    }
    return kept;
}
