/* Angle helpers [rad] shared by the models. */
#ifndef NAVCOSIM_ANGLES_H
#define NAVCOSIM_ANGLES_H

#include <math.h>

#ifndef M_PI /* not declared by <math.h> under -std=c99 */
#define M_PI 3.14159265358979323846
#endif

/* MATLAB's wrapToPi: an angle in [-pi, pi] comes back unchanged (bit for bit, both ends included);
 * any other is shifted by whole turns into (-pi, pi]. */
static inline double wrap_to_pi(double angle) {
    if (fabs(angle) <= M_PI) return angle;
    double shifted = fmod(angle + M_PI, 2.0 * M_PI);
    if (shifted < 0.0) shifted += 2.0 * M_PI;
    if (shifted == 0.0 && angle + M_PI > 0.0) shifted = 2.0 * M_PI; /* +pi stays +pi */
    return shifted - M_PI;
}

/* A vehicle heading in (-pi, pi]: unlike wrap_to_pi, -pi becomes pi, so a pose has one
 * representation (the kinematics FMUs' theta output). */
static inline double wrap_heading(double angle) {
    double wrapped = fmod(angle + M_PI, 2.0 * M_PI);
    if (wrapped <= 0.0) wrapped += 2.0 * M_PI;
    return wrapped - M_PI;
}

/* An angle shifted by pi into (-pi/2, pi/2]: the steering angle with the same tangent, i.e. the
 * same turning curvature, as atan2 gives for a (v, omega) command with v < 0. */
static inline double fold_to_half_pi(double angle) {
    if (angle > M_PI / 2.0) return angle - M_PI;
    if (angle <= -M_PI / 2.0) return angle + M_PI;
    return angle;
}

#endif
