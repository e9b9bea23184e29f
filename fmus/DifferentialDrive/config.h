/* DifferentialDrive: MATLAB's differentialDriveKinematics as an FMU (thesis eqs 4.4 and 4.5). */
#ifndef DIFFERENTIAL_DRIVE_CONFIG_H
#define DIFFERENTIAL_DRIVE_CONFIG_H

#define MODEL_IDENTIFIER "DifferentialDrive"
#define MODEL_GUID "{0a1ebf92-88de-4ee3-9d6b-a0fca9cd1c6b}"

/* Value references, as in modelDescription.xml. */
enum {
    VR_WHEEL_RADIUS = 1,
    VR_TRACK_WIDTH = 2,
    VR_WHEEL_SPEED_MIN = 3,
    VR_WHEEL_SPEED_MAX = 4,
    VR_X0 = 5,
    VR_Y0 = 6,
    VR_THETA0 = 7,
    VR_V = 10,
    VR_OMEGA = 11,
    VR_WHEEL_SPEED_LEFT = 12,
    VR_WHEEL_SPEED_RIGHT = 13,
    VR_X = 20,
    VR_Y = 21,
    VR_THETA = 22,
    VR_V_ACTUAL = 23,
    VR_OMEGA_ACTUAL = 24,
    VR_WHEEL_SPEED_LEFT_ACTUAL = 25,
    VR_WHEEL_SPEED_RIGHT_ACTUAL = 26,
    VR_INPUT_MODE = 30, /* Integer */
};

enum { INPUT_VELOCITIES = 0, INPUT_WHEEL_SPEEDS = 1 };

struct ModelData {
    /* parameters */
    int input_mode;
    double wheel_radius, track_width;        /* [m] */
    double wheel_speed_min, wheel_speed_max; /* [rad/s] */
    double x0, y0, theta0;                   /* [m, m, rad] */
    /* inputs */
    double v, omega;                                /* [m/s, rad/s] */
    double wheel_speed_left, wheel_speed_right;     /* [rad/s] */
    /* outputs (the pose is also the state) */
    double x, y, theta;
    double v_actual, omega_actual;
    double wheel_speed_left_actual, wheel_speed_right_actual;
};

#endif
