/* ArtificialPotentialField: Khatib-style potential-field obstacle avoidance with the ports of
 * VectorFieldHistogram (a drop-in for it in front of the AvoidanceMixer). */
#ifndef APF_CONFIG_H
#define APF_CONFIG_H

#include <stdbool.h>

#define MODEL_IDENTIFIER "ArtificialPotentialField"
#define MODEL_GUID "{a0764ad2-2fce-4367-acb0-8292e0bec0f1}"

#define APF_MAX_READINGS 720 /* capacity of the NaN-padded ranges/angles inputs (as VFH) */

/* Value references, unique per type; the ports VFH also has keep VFH's numbers. ranges[k] has
 * VR_RANGES + k - 1. */
enum {
    VR_DISTANCE_LIMIT_MIN = 0,
    VR_DISTANCE_LIMIT_MAX = 1,
    VR_ROBOT_RADIUS = 2,
    VR_SAFETY_DISTANCE = 3,
    VR_INFLUENCE_DISTANCE = 4,
    VR_ATTRACTIVE_GAIN = 5,
    VR_REPULSIVE_GAIN = 6,
    VR_MAX_TARGET_DEVIATION = 7,
    VR_TARGET_DIR = 20,
    VR_STEERING_DIR = 30,
    VR_FORCE_X = 31,
    VR_FORCE_Y = 32,
    VR_NEAREST_DISTANCE = 33,
    VR_RANGES = 1000,
    VR_ANGLES = 2000
};
/* A changed reading angle invalidates the cached trigonometry (model_real_changed). */
#define MODEL_WATCHES_REAL(vr) ((vr) >= VR_ANGLES && (vr) < VR_ANGLES + APF_MAX_READINGS)
enum { VR_REPELLING_READINGS = 10, VR_DIRECTION_STATUS = 11 }; /* Integer */
enum { VR_TARGET_DIR_FREE = 0 };                               /* Boolean */

/* What steering_dir is (the `direction_status` output; NaN for the last two), see apf.c. */
enum { APF_FORCE = 0, APF_DEFLECTED = 1, APF_TRAPPED = 2, APF_ENCLOSED = 3 };

struct ModelData {
    /* parameters */
    double distance_limit_min, distance_limit_max; /* m */
    double robot_radius, safety_distance;          /* m */
    double influence_distance;                     /* m, clearance beyond which a return does not repel */
    double attractive_gain;                        /* 1 */
    double repulsive_gain;                         /* m^3 */
    double max_target_deviation;                   /* rad */
    /* inputs */
    double ranges[APF_MAX_READINGS], angles[APF_MAX_READINGS]; /* m, rad; NaN = no reading */
    double target_dir;                                         /* rad */
    /* outputs */
    double steering_dir;     /* rad, NaN when no direction (see direction_status) */
    double force_x, force_y; /* resultant force, vehicle frame, 1 */
    double nearest_distance; /* m, NaN when no reading is inside the distance limits */
    int repelling_readings, direction_status;
    bool target_dir_free;
    /* Cosine and sine of each reading angle, recomputed only when an angle input changes. */
    bool angles_changed;
    double reading_cos[APF_MAX_READINGS], reading_sin[APF_MAX_READINGS];
    int close_readings[APF_MAX_READINGS]; /* scratch: readings inside robot_radius + safety_distance */
};

#endif
