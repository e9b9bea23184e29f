/* AvoidanceMixer: the "Adjust velocities to avoid obstacles" logic (thesis 4.3.3, Figure 4.12). */
#ifndef AVOIDANCE_MIXER_CONFIG_H
#define AVOIDANCE_MIXER_CONFIG_H

#include <stdbool.h>

#define MODEL_IDENTIFIER "AvoidanceMixer"
#define MODEL_GUID "{5d0c7a2e-7f0b-4c59-9d8e-2f1a6b3c4d03}"

enum { VEHICLE_DIFFERENTIAL = 0, VEHICLE_BICYCLE = 1 };
enum { MODE_FOLLOW = 0, MODE_AVOID = 1, MODE_RECOVER = 2, MODE_STOPPED = 3 };

enum { /* Real value references */
    VR_WHEELBASE = 0,
    VR_MAX_STEERING_ANGLE = 1,
    VR_DIRECTION_TOLERANCE = 2,
    VR_AVOID_GAIN = 3,
    VR_AVOID_SPEED_FACTOR = 4,
    VR_RECOVERY_ANGULAR_VELOCITY = 5,
    VR_RECOVERY_LINEAR_VELOCITY = 6,
    VR_AVOID_STEERING_GAIN = 7,
    VR_RECOVERY_MIN_DURATION = 8,
    VR_AVOID_HOLD_TIME = 9,
    VR_V_IN = 10,
    VR_OMEGA_IN = 11,
    VR_TARGET_DIR = 12,
    VR_STEERING_DIR = 13,
    VR_V = 20,
    VR_OMEGA = 21,
    VR_STEERING_ANGLE = 22
};
enum { VR_VEHICLE_TYPE = 0, VR_MODE = 10 }; /* Integer */
enum { VR_GOAL_REACHED = 0 };               /* Boolean */

struct ModelData {
    /* parameters */
    int vehicle_type;                 /* 0 differential drive, 1 bicycle */
    double wheelbase;                 /* m (bicycle) */
    double max_steering_angle;        /* rad (bicycle) */
    double direction_tolerance;       /* rad */
    double avoid_gain;                /* 1/s: omega = avoid_gain * steering_dir */
    double avoid_speed_factor;        /* v multiplier while avoiding (1 = MATLAB: v kept) */
    double recovery_angular_velocity; /* rad/s, magnitude of the on-the-spot turn */
    double recovery_linear_velocity;  /* m/s, magnitude of the bicycle's reversing speed */
    double avoid_steering_gain;       /* bicycle: steering_angle = gain * steering_dir while avoiding */
    double recovery_min_duration;     /* s: once recovering, keep recovering at least this long */
    double avoid_hold_time;           /* s: keep the last avoidance offset this long after VFH frees the target */
    /* inputs */
    double v_in, omega_in, target_dir, steering_dir;
    bool goal_reached;
    /* outputs */
    double v, omega, steering_angle;
    int mode;
    /* state */
    double recovery_sign; /* +1 turn left (CCW), -1 right: toward the side that was last free */
    double recovery_elapsed; /* s spent in the current recovery (0 when not recovering) */
    double avoid_offset;     /* rad: steering_dir - target_dir of the last avoidance */
    double hold_elapsed;     /* s since VFH last intervened (while holding its offset) */
};

#endif
