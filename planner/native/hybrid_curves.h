/* Reeds-Shepp and Dubins curves in the normalised frame (start at the origin heading +x, R = 1):
 * the C of planner/reeds_shepp.py and planner/dubins.py (their docstrings derive the formulas),
 * operation for operation. Candidates go into row-major buffers of `stride` columns: letters
 * (+1 left arc, 0 straight, -1 right arc) and signed lengths (negative = reverse). */
#ifndef NAVCOSIM_HYBRID_CURVES_H
#define NAVCOSIM_HYBRID_CURVES_H

#include "hybrid_geometry.h"

#define HY_RS_MAX_CANDIDATES 64
#define HY_DUBINS_MAX_CANDIDATES 8
#define HY_SIGN_TOL 1e-10     /* a zero-length segment that rounding made -1e-15 still counts */
#define HY_FULL_TURN_TOL 1e-9 /* a Dubins turn this close to 2 pi is a zero-length arc */

static const int64_t HY_RS_LETTERS[9][5] = {
    {1, 0, 1, 0, 0},   /* LSL   (CSC) */
    {1, 0, -1, 0, 0},  /* LSR   (CSC) */
    {1, -1, 1, 0, 0},  /* LRL   (C|C|C and C|CC) */
    {1, -1, 1, -1, 0}, /* LRLR  (CCu|CuC), first branch */
    {1, -1, 1, -1, 0}, /* LRLR  (CCu|CuC), second branch */
    {1, -1, 1, -1, 0}, /* LRLR  (C|CuCu|C) */
    {1, -1, 0, 1, 0},  /* LRSL  (C|C[pi/2]SC) */
    {1, -1, 0, -1, 0}, /* LRSR  (C|C[pi/2]SC) */
    {1, -1, 0, 1, -1}, /* LRSLR (C|C[pi/2]SC[pi/2]|C) */
};
static const int64_t HY_RS_SEGMENTS[9] = {3, 3, 3, 4, 4, 4, 4, 4, 5};
static const int HY_RS_HAS_BACKWARDS[9] = {0, 0, 1, 0, 0, 0, 1, 1, 0};

/* Solve Reeds-Shepp base formula `family` for goal (x, y, phi); signed lengths into out[5]. */
static int hy_rs_base(int family, double x, double y, double phi, double *out) {
    double sin_phi = sin(phi);
    double cos_phi = cos(phi);
    double distance, angle, u, t, v, cos_u, root;
    if (family == 0) { /* L+ S+ L+ */
        double px = x - sin_phi, py = y - 1.0 + cos_phi;
        u = hypot(px, py);
        t = atan2(py, px);
        t = hy_wrap_angle(t);
        v = hy_wrap_angle(phi - t);
        out[0] = t, out[1] = u, out[2] = v;
        return t >= -HY_SIGN_TOL && v >= -HY_SIGN_TOL;
    }
    if (family == 1) { /* L+ S+ R+ */
        double px = x + sin_phi, py = y - 1.0 - cos_phi;
        distance = hypot(px, py);
        angle = atan2(py, px);
        if (distance < 2.0) return 0;
        u = sqrt(hy_max(distance * distance - 4.0, 0.0));
        t = hy_wrap_angle(angle + atan2(2.0, u));
        v = hy_wrap_angle(t - phi);
        out[0] = t, out[1] = u, out[2] = v;
        return t >= -HY_SIGN_TOL && v >= -HY_SIGN_TOL;
    }
    if (family == 2) { /* L+ R- L+/- */
        double px = x - sin_phi, py = y - 1.0 + cos_phi;
        distance = hypot(px, py);
        angle = atan2(py, px);
        if (distance > 4.0) return 0;
        u = -2.0 * asin(distance / 4.0);
        t = hy_wrap_angle(angle + 0.5 * u + HY_PI);
        v = hy_wrap_angle(phi - t + u);
        out[0] = t, out[1] = u, out[2] = v;
        return t >= -HY_SIGN_TOL;
    }
    if (family == 3 || family == 4) { /* L+ R+ L- R- */
        double px = x + sin_phi, py = y - 1.0 - cos_phi;
        distance = hypot(px, py);
        angle = atan2(py, px);
        if (family == 3)
            cos_u = (2.0 + distance) / 4.0;
        else
            cos_u = (2.0 - distance) / 4.0;
        if (cos_u > 1.0 || cos_u < -1.0) return 0;
        u = acos(cos_u);
        t = family == 3 ? hy_wrap_angle(angle + u + HY_HALF_PI) : hy_wrap_angle(angle + u - HY_HALF_PI);
        v = hy_wrap_angle(t - 2.0 * u - phi);
        out[0] = t, out[1] = u, out[2] = -u, out[3] = v;
        return t >= -HY_SIGN_TOL && v <= HY_SIGN_TOL;
    }
    if (family == 5) { /* L+ R- L- R+ */
        double px = x + sin_phi, py = y - 1.0 - cos_phi;
        distance = hypot(px, py);
        angle = atan2(py, px);
        cos_u = (20.0 - distance * distance) / 16.0;
        if (cos_u > 1.0 || cos_u < -1.0) return 0;
        u = acos(cos_u);
        t = hy_wrap_angle(angle + HY_HALF_PI + atan2(sin(u), 2.0 - cos_u));
        v = hy_wrap_angle(t - phi);
        out[0] = t, out[1] = -u, out[2] = -u, out[3] = v;
        return t >= -HY_SIGN_TOL && v >= -HY_SIGN_TOL;
    }
    if (family == 6) { /* L+ R-(pi/2) S- L- */
        double px = x - sin_phi, py = y - 1.0 + cos_phi;
        distance = hypot(px, py);
        angle = atan2(py, px);
        if (distance < 2.0) return 0;
        root = sqrt(distance * distance - 4.0);
        u = root - 2.0;
        t = hy_wrap_angle(angle - HY_PI - atan2(root, 2.0));
        v = hy_wrap_angle(t + HY_HALF_PI - phi);
        out[0] = t, out[1] = -HY_HALF_PI, out[2] = -u, out[3] = -v;
        return u >= -HY_SIGN_TOL && t >= -HY_SIGN_TOL && v >= -HY_SIGN_TOL;
    }
    if (family == 7) { /* L+ R-(pi/2) S- R- */
        double px = x + sin_phi, py = y - 1.0 - cos_phi;
        distance = hypot(px, py);
        angle = atan2(py, px);
        u = distance - 2.0;
        t = hy_wrap_angle(angle + HY_HALF_PI);
        v = hy_wrap_angle(phi - t - HY_HALF_PI);
        out[0] = t, out[1] = -HY_HALF_PI, out[2] = -u, out[3] = -v;
        return u >= -HY_SIGN_TOL && t >= -HY_SIGN_TOL && v >= -HY_SIGN_TOL;
    }
    /* family 8, L+ R-(pi/2) S- L-(pi/2) R+ */
    double px = x + sin_phi, py = y - 1.0 - cos_phi;
    distance = hypot(px, py);
    angle = atan2(py, px);
    if (distance < 2.0) return 0;
    root = sqrt(distance * distance - 4.0);
    u = root - 4.0;
    t = hy_wrap_angle(angle - HY_PI - atan2(root, 2.0));
    v = hy_wrap_angle(t - phi);
    out[0] = t, out[1] = -HY_HALF_PI, out[2] = -u, out[3] = -HY_HALF_PI, out[4] = v;
    return u >= -HY_SIGN_TOL && t >= -HY_SIGN_TOL && v >= -HY_SIGN_TOL;
}

/* All Reeds-Shepp candidates from the origin to (x, y, phi), R = 1: letters and signed lengths into
 * K x stride buffers (K >= HY_RS_MAX_CANDIDATES, stride >= 5; columns 0-4 written); returns K. */
static int64_t hy_rs_enumerate(double x, double y, double phi, int64_t *letters, double *lengths, int64_t stride) {
    int64_t count = 0;
    double base_lengths[5] = {0.0, 0.0, 0.0, 0.0, 0.0};
    double cos_phi = cos(phi);
    double sin_phi = sin(phi);
    for (int family = 0; family < 9; family++) {
        int64_t segments = HY_RS_SEGMENTS[family];
        for (int backwards = 0; backwards < (HY_RS_HAS_BACKWARDS[family] ? 2 : 1); backwards++) {
            double bx, by;
            if (backwards) {
                bx = x * cos_phi + y * sin_phi;
                by = x * sin_phi - y * cos_phi;
            } else {
                bx = x, by = y;
            }
            for (int flip = 0; flip < 4; flip++) {
                int time_flip = flip & 1;
                int reflect = flip >> 1;
                double fx = time_flip ? -bx : bx;
                double fy = reflect ? -by : by;
                double fphi = (time_flip ^ reflect) ? -phi : phi;
                for (int k = 0; k < 5; k++) base_lengths[k] = 0.0;
                if (!hy_rs_base(family, fx, fy, fphi, base_lengths)) continue;
                for (int64_t k = 0; k < 5; k++) {
                    int64_t source = backwards ? segments - 1 - k : k;
                    if (k < segments) {
                        double length = base_lengths[source];
                        int64_t letter = HY_RS_LETTERS[family][source];
                        lengths[count * stride + k] = time_flip ? -length : length;
                        letters[count * stride + k] = reflect ? -letter : letter;
                    } else {
                        lengths[count * stride + k] = 0.0;
                        letters[count * stride + k] = 0;
                    }
                }
                count++;
            }
        }
    }
    return count;
}

/* Length of the shortest Reeds-Shepp path from the origin to (x, y, phi), R = 1 (buffers as above). */
static double hy_rs_shortest(double x, double y, double phi, int64_t *letters, double *lengths, int64_t stride) {
    int64_t count = hy_rs_enumerate(x, y, phi, letters, lengths, stride);
    double best = INFINITY;
    for (int64_t k = 0; k < count; k++) {
        double total = 0.0;
        for (int j = 0; j < 5; j++) total += fabs(lengths[k * stride + j]);
        best = hy_min(best, total);
    }
    return best;
}

static const int64_t HY_DUBINS_LETTERS[4][3] = {{1, 0, 1}, {1, 0, -1}, {1, -1, 1}, {1, -1, 1}};

/* Angle [rad] in [0, 2pi), with values within rounding of 2pi mapped to 0. */
static inline double hy_mod_turn(double angle) {
    double wrapped = hy_py_mod(angle, HY_TWO_PI);
    if (wrapped > HY_TWO_PI - HY_FULL_TURN_TOL) return 0.0;
    return wrapped;
}

/* Solve Dubins base word `family` (0 LSL, 1 LSR, 2/3 LRL) for goal (x, y, phi), R = 1. */
static int hy_dubins_base(int family, double x, double y, double phi, double *out) {
    double sin_phi = sin(phi);
    double cos_phi = cos(phi);
    double dx, dy, distance, u, t;
    if (family == 0) {
        dx = x - sin_phi;
        dy = y - 1.0 + cos_phi;
        t = hy_mod_turn(atan2(dy, dx));
        out[0] = t, out[1] = hypot(dx, dy), out[2] = hy_mod_turn(phi - t);
        return 1;
    }
    if (family == 1) {
        dx = x + sin_phi;
        dy = y - 1.0 - cos_phi;
        distance = hypot(dx, dy);
        if (distance < 2.0) return 0;
        u = sqrt(hy_max(distance * distance - 4.0, 0.0));
        t = hy_mod_turn(atan2(dy, dx) + atan2(2.0, u));
        out[0] = t, out[1] = u, out[2] = hy_mod_turn(t - phi);
        return 1;
    }
    dx = x - sin_phi;
    dy = y - 1.0 + cos_phi;
    distance = hypot(dx, dy);
    if (distance > 4.0) return 0;
    u = 2.0 * asin(distance / 4.0);
    if (family == 3) u = HY_TWO_PI - u;
    t = hy_mod_turn(atan2(dy, dx) + 0.5 * u);
    out[0] = t, out[1] = u, out[2] = hy_mod_turn(phi - t + u);
    return 1;
}

/* All Dubins candidates from the origin to (x, y, phi), R = 1, into K x stride buffers (stride >= 3;
 * columns 0-2 written); returns K (<= HY_DUBINS_MAX_CANDIDATES). */
static int64_t hy_dubins_enumerate(double x, double y, double phi, int64_t *letters, double *lengths,
                                   int64_t stride) {
    int64_t count = 0;
    double base_lengths[3] = {0.0, 0.0, 0.0};
    for (int family = 0; family < 4; family++) {
        for (int reflect = 0; reflect < 2; reflect++) {
            double fy = reflect ? -y : y;
            double fphi = reflect ? -phi : phi;
            if (!hy_dubins_base(family, x, fy, fphi, base_lengths)) continue;
            for (int k = 0; k < 3; k++) {
                lengths[count * stride + k] = base_lengths[k];
                letters[count * stride + k] = reflect ? -HY_DUBINS_LETTERS[family][k] : HY_DUBINS_LETTERS[family][k];
            }
            count++;
        }
    }
    return count;
}

/* Length of the shortest Dubins path from the origin to (x, y, phi), R = 1 (buffers as above). */
static double hy_dubins_shortest(double x, double y, double phi, int64_t *letters, double *lengths,
                                 int64_t stride) {
    int64_t count = hy_dubins_enumerate(x, y, phi, letters, lengths, stride);
    double best = INFINITY;
    for (int64_t k = 0; k < count; k++) {
        const double *row = lengths + k * stride;
        best = hy_min(best, row[0] + row[1] + row[2]);
    }
    return best;
}

/* The goal in the start's frame, scaled by 1/radius: (x, y, phi) for the R = 1 formulas. */
static inline void hy_normalize(double start_x, double start_y, double start_theta, double goal_x, double goal_y,
                                double goal_theta, double radius, double *x, double *y, double *phi) {
    double dx = goal_x - start_x;
    double dy = goal_y - start_y;
    double cos_t = cos(start_theta);
    double sin_t = sin(start_theta);
    *x = (cos_t * dx + sin_t * dy) / radius;
    *y = (-sin_t * dx + cos_t * dy) / radius;
    *phi = hy_wrap_angle(goal_theta - start_theta);
}

#endif
