/* Bicycle: MATLAB's bicycleKinematics as an FMU, with the thesis's three steering modes (eqs 4.9-4.11). */
#ifndef BICYCLE_CONFIG_H
#define BICYCLE_CONFIG_H

#define MODEL_IDENTIFIER "Bicycle"
#define MODEL_GUID "{b9d705fc-16da-44a9-b5b4-68fedb1b6836}"

/* Value references, as in modelDescription.xml. */
enum {
    VR_WHEELBASE = 1,
    VR_REAR_AXLE_DISTANCE = 2,
    VR_MAX_STEERING_ANGLE = 3,
    VR_SPEED_MIN = 4,
    VR_SPEED_MAX = 5,
    VR_X0 = 6,
    VR_Y0 = 7,
    VR_THETA0 = 8,
    VR_V = 10,
    VR_STEERING_ANGLE = 11,
    VR_OMEGA = 12,
    VR_X = 20,
    VR_Y = 21,
    VR_THETA = 22,
    VR_V_ACTUAL = 23,
    VR_STEERING_ANGLE_ACTUAL = 24,
    VR_YAW_RATE = 25,
    VR_SLIP_ANGLE = 26,
    VR_INPUT_MODE = 30,    /* Integer */
    VR_STEERING_MODE = 31, /* Integer */
};

enum { INPUT_STEERING_ANGLE = 0, INPUT_YAW_RATE = 1 };
enum { STEERING_FRONT = 0, STEERING_ZERO_SIDESLIP = 1, STEERING_PARALLEL = 2 };

struct ModelData {
    /* parameters */
    int input_mode, steering_mode;
    double wheelbase;                   /* [m] */
    double rear_axle_distance;          /* [m] reference point ahead of the rear axle */
    double max_steering_angle;          /* [rad] */
    double speed_min, speed_max;        /* [m/s] */
    double x0, y0, theta0;              /* [m, m, rad] */
    /* inputs */
    double v, steering_angle, omega;    /* [m/s, rad, rad/s] */
    /* outputs (the pose is also the state) */
    double x, y, theta;
    double v_actual, steering_angle_actual, yaw_rate, slip_angle;
    /* derived in apply_inputs, constant over a step */
    double point_speed; /* [m/s] speed of the reference point, signed as v */
};

#endif
