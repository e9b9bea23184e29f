/* Exact Euclidean distance transform and 3 x 3 dilation of a boolean grid (planner.inflation).
 * Loaded with native.load.
 *
 * Distance transform: the separable squared transform of Felzenszwalb and Huttenlocher ("Distance
 * Transforms of Sampled Functions", 2012). The squared distance from cell (r, c) to the nearest
 * feature cell is min over features (r', c') of (sr (r - r'))^2 + (sc (c - c'))^2 (sr, sc: the
 * spacing of rows and columns). Its minimum over r' for each column is a 1-D transform of a
 * function that is 0 on features and infinite elsewhere; the minimum of that over c' along each
 * row is a second 1-D transform. A 1-D transform min_q f(q) + (s (p - q))^2 is the lower envelope
 * of the parabolas rooted at each q, found in one left-to-right sweep that keeps the parabolas
 * still on the envelope and where each takes over from the previous one, then read out in a second
 * sweep: O(n) per line, exact (no chamfer or 8-point approximation).
 *
 * Rounding: each value is formed as f(q) + (s (p - q))^2, i.e. (sr dr)^2 + (sc dc)^2 summed
 * rows first, the order in which scipy.ndimage.distance_transform_edt sums; with unit spacing every
 * squared distance is an integer, exact in a double, so the square roots equal scipy's bit for bit.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

/* The 1-D transform of the n samples f[0..n) into d[0], d[stride], ...: d[p] = min over q with
 * finite f[q] of f[q] + (spacing (p - q))^2, INFINITY when every f is infinite. f and d may not
 * overlap. roots (n) and bounds (n + 1) are scratch. */
static void transform_line(const double *f, double *d, int64_t n, int64_t stride, double spacing,
                           int64_t *roots, double *bounds) {
    double spacing2 = spacing * spacing;
    int64_t k = -1; /* index of the envelope's last parabola */
    for (int64_t q = 0; q < n; q++) {
        double fq = f[q];
        if (fq == INFINITY) continue;
        double s = -INFINITY;
        while (k >= 0) {
            /* Where the parabola of q meets that of roots[k]: it takes over from there on. */
            int64_t v = roots[k];
            double fv = f[v];
            s = ((fq + spacing2 * (double)(q * q)) - (fv + spacing2 * (double)(v * v))) /
                (2.0 * spacing2 * (double)(q - v));
            if (s > bounds[k]) break;
            k--; /* roots[k] is nowhere lowest: drop it */
        }
        if (k < 0) s = -INFINITY;
        k++;
        roots[k] = q;
        bounds[k] = s;
        bounds[k + 1] = INFINITY;
    }
    if (k < 0) {
        for (int64_t p = 0; p < n; p++) d[p * stride] = INFINITY;
        return;
    }
    int64_t j = 0;
    for (int64_t p = 0; p < n; p++) {
        while (bounds[j + 1] < (double)p) j++;
        double offset = spacing * (double)(p - roots[j]);
        d[p * stride] = f[roots[j]] + offset * offset;
    }
}

/* distance[rows x cols] (row-major): Euclidean distance from each cell to the nearest cell whose
 * feature byte is non-zero, rows `row_spacing` and columns `col_spacing` apart; INFINITY everywhere
 * when there is none. Returns 0, or -1 when scratch memory could not be had. */
int64_t navcosim_distance_transform(const uint8_t *feature, int64_t rows, int64_t cols, double row_spacing,
                                    double col_spacing, double *distance) {
    int64_t longest = rows > cols ? rows : cols;
    double *line = malloc(sizeof(double) * (size_t)(2 * longest + 1));
    double *column = malloc(sizeof(double) * (size_t)rows);
    int64_t *roots = malloc(sizeof(int64_t) * (size_t)longest);
    if (line == NULL || column == NULL || roots == NULL) {
        free(line);
        free(column);
        free(roots);
        return -1;
    }
    double *bounds = line + longest;
    for (int64_t c = 0; c < cols; c++) { /* along each column: squared distance to the nearest feature row */
        for (int64_t r = 0; r < rows; r++) column[r] = feature[r * cols + c] ? 0.0 : INFINITY;
        transform_line(column, distance + c, rows, cols, row_spacing, roots, bounds);
    }
    for (int64_t r = 0; r < rows; r++) { /* then along each row, over those */
        double *row = distance + r * cols;
        for (int64_t c = 0; c < cols; c++) line[c] = row[c];
        transform_line(line, row, cols, 1, col_spacing, roots, bounds);
        for (int64_t c = 0; c < cols; c++) row[c] = sqrt(row[c]);
    }
    free(line);
    free(column);
    free(roots);
    return 0;
}

/* out[rows x cols] = 1 where any of the 3 x 3 cells centred on the cell (those on the grid) is
 * non-zero in `in`, else 0: binary dilation by a full 3 x 3 square, nothing beyond the border. */
void navcosim_dilate_square(const uint8_t *in, int64_t rows, int64_t cols, uint8_t *out) {
    for (int64_t r = 0; r < rows; r++) {
        int64_t first_row = r > 0 ? r - 1 : 0;
        int64_t last_row = r + 1 < rows ? r + 1 : rows - 1;
        for (int64_t c = 0; c < cols; c++) {
            int64_t first_col = c > 0 ? c - 1 : 0;
            int64_t last_col = c + 1 < cols ? c + 1 : cols - 1;
            uint8_t any = 0;
            for (int64_t i = first_row; i <= last_row && !any; i++)
                for (int64_t j = first_col; j <= last_col; j++)
                    if (in[i * cols + j]) {
                        any = 1;
                        break;
                    }
            out[r * cols + c] = any;
        }
    }
}
