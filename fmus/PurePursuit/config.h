/* PurePursuit: MATLAB-compatible pure-pursuit path follower (controllerPurePursuit). */
#ifndef PURE_PURSUIT_CONFIG_H
#define PURE_PURSUIT_CONFIG_H

#include <stdbool.h>

#define MODEL_IDENTIFIER "PurePursuit"
#define MODEL_GUID "{5d0c7a2e-7f0b-4c59-9d8e-2f1a6b3c4d01}"

/* Capacity of the NaN-padded waypoint input (rows of the N x 2 array). */
#define PP_MAX_WAYPOINTS 1000

/* Value references, unique per type. waypoints[k,1] has VR_WAYPOINTS_X + k - 1. */
enum {
    VR_DESIRED_LINEAR_VELOCITY = 0,
    VR_MAX_ANGULAR_VELOCITY = 1,
    VR_LOOKAHEAD_DISTANCE = 2,
    VR_GOAL_TOLERANCE = 3,
    VR_X = 10,
    VR_Y = 11,
    VR_THETA = 12,
    VR_V = 20,
    VR_OMEGA = 21,
    VR_TARGET_DIR = 22,
    VR_LOOKAHEAD_X = 23,
    VR_LOOKAHEAD_Y = 24,
    VR_GOAL_DISTANCE = 25,
    VR_WAYPOINTS_X = 1000,
    VR_WAYPOINTS_Y = 2000
};
/* A changed waypoint element marks a new plan (model_real_changed). */
#define MODEL_WATCHES_REAL(vr) ((vr) >= VR_WAYPOINTS_X && (vr) < VR_WAYPOINTS_Y + PP_MAX_WAYPOINTS)
enum { VR_ANGULAR_VELOCITY_LAW = 0 };                /* Integer */
enum { VR_GOAL_REACHED = 0 };                        /* Boolean */

/* Where the projection point sits on the path: kept between steps, so it only moves forward. */
typedef struct {
    bool valid;   /* false: next step searches every segment from waypoint 1 */
    int segment;  /* index of the segment [path[segment], path[segment + 1]] */
    double x, y;
} ProjectionState;

struct ModelData {
    /* parameters */
    double desired_linear_velocity; /* m/s */
    double max_angular_velocity;    /* rad/s */
    double lookahead_distance;      /* m */
    double goal_tolerance;          /* m */
    int angular_velocity_law;       /* 0 MATLAB 2 sin(alpha)/L, 1 nav2 v * kappa */
    /* inputs */
    double x, y, theta;
    double waypoints_x[PP_MAX_WAYPOINTS], waypoints_y[PP_MAX_WAYPOINTS];
    /* outputs */
    double v, omega, target_dir, lookahead_x, lookahead_y, goal_distance;
    bool goal_reached;
    /* state */
    bool waypoints_changed;          /* set when any waypoint input element changes value */
    int path_count;                  /* rows of the waypoint input without NaN */
    double path_x[PP_MAX_WAYPOINTS], path_y[PP_MAX_WAYPOINTS];
    ProjectionState projection;
};

#endif
