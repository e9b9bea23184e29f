/*
 * Exact planar motion of a rigid body over one step with constant body-frame velocity.
 *
 * A point moving at constant speed with a constant angle `heading_offset` to the body axis,
 * while the body turns at a constant yaw rate, follows a circular arc (a straight line when the
 * yaw rate is zero). The chord of that arc is
 *     dx = speed*h*cos(theta + offset + dtheta/2) * sinc(dtheta/2),   dtheta = yaw_rate*h
 *     dy = speed*h*sin(theta + offset + dtheta/2) * sinc(dtheta/2)
 * which is the closed form v/omega*(sin(theta+dtheta) - sin(theta)), ... written so it stays
 * accurate as the yaw rate goes to zero (no division by omega).
 */
#ifndef NAVCOSIM_PLANAR_MOTION_H
#define NAVCOSIM_PLANAR_MOTION_H

#include <math.h>
#include <stdbool.h>

#include "angles.h"
#include "model.h"

/* sin(a)/a; the Taylor series below |a| = 1e-4 has a truncation error under 1e-20. */
static inline double planar_sinc(double a) {
    return fabs(a) < 1e-4 ? 1.0 - a * a / 6.0 : sin(a) / a;
}

/* Start the pose (x [m], y [m], theta [rad]) at the parameters x0, y0, theta0, theta wrapped;
 * logs and returns false when one of them is not finite. */
static inline bool planar_start_pose(ModelInstance *comp, double x0, double y0, double theta0, double *x, double *y,
                                     double *theta) {
    if (!isfinite(x0) || !isfinite(y0) || !isfinite(theta0)) {
        model_log_error(comp, "parameters x0, y0, theta0 must be finite");
        return false;
    }
    *x = x0;
    *y = y0;
    *theta = wrap_heading(theta0);
    return true;
}

/* Advance pose (x [m], y [m], theta [rad]) by h [s]; speed [m/s] of the tracked point, signed. */
static inline void planar_advance(double *x, double *y, double *theta, double speed, double heading_offset,
                                  double yaw_rate, double h) {
    double turn = yaw_rate * h;
    double chord = speed * h * planar_sinc(0.5 * turn);
    double direction = *theta + heading_offset + 0.5 * turn;
    *x += chord * cos(direction);
    *y += chord * sin(direction);
    *theta = wrap_heading(*theta + turn);
}

#endif
