/* VectorFieldHistogram: VFH+ obstacle avoidance as MATLAB's controllerVFH computes it. */
#ifndef VFH_CONFIG_H
#define VFH_CONFIG_H

#include <stdbool.h>

#define MODEL_IDENTIFIER "VectorFieldHistogram"
#define MODEL_GUID "{5d0c7a2e-7f0b-4c59-9d8e-2f1a6b3c4d02}"

#define VFH_MAX_READINGS 720 /* capacity of the NaN-padded ranges/angles inputs */
#define VFH_MAX_SECTORS 720  /* largest num_angular_sectors (0.5 degree sectors) */
/* At most ceil(N/2) valleys of <= 2 candidates each, plus target, 0 and previous. */
#define VFH_MAX_CANDIDATES (VFH_MAX_SECTORS + 4)

/* Value references, unique per type. ranges[k] has VR_RANGES + k - 1. */
enum {
    VR_DISTANCE_LIMIT_MIN = 0,
    VR_DISTANCE_LIMIT_MAX = 1,
    VR_ROBOT_RADIUS = 2,
    VR_SAFETY_DISTANCE = 3,
    VR_MIN_TURNING_RADIUS = 4,
    VR_TARGET_DIRECTION_WEIGHT = 5,
    VR_CURRENT_DIRECTION_WEIGHT = 6,
    VR_PREVIOUS_DIRECTION_WEIGHT = 7,
    VR_HISTOGRAM_THRESHOLD_LOW = 8,
    VR_HISTOGRAM_THRESHOLD_HIGH = 9,
    VR_NARROW_OPENING_THRESHOLD = 10,
    VR_TARGET_DIR = 20,
    VR_STEERING_DIR = 30,
    VR_RANGES = 1000,
    VR_ANGLES = 2000
};
/* A changed reading angle invalidates the cached trigonometry (model_real_changed). */
#define MODEL_WATCHES_REAL(vr) ((vr) >= VR_ANGLES && (vr) < VR_ANGLES + VFH_MAX_READINGS)
enum { VR_NUM_ANGULAR_SECTORS = 0, VR_FREE_SECTORS = 10, VR_NUM_VALLEYS = 11 }; /* Integer */
enum { VR_TARGET_DIR_FREE = 0 };                                                /* Boolean */

struct ModelData {
    /* parameters */
    int num_angular_sectors;
    double distance_limit_min, distance_limit_max;     /* m */
    double robot_radius, safety_distance;              /* m */
    double min_turning_radius;                         /* m */
    double target_direction_weight, current_direction_weight, previous_direction_weight;
    double histogram_threshold_low, histogram_threshold_high;
    double narrow_opening_threshold;                   /* rad */
    /* inputs */
    double ranges[VFH_MAX_READINGS], angles[VFH_MAX_READINGS]; /* m, rad; NaN = no reading */
    double target_dir;                                         /* rad */
    /* outputs */
    double steering_dir; /* rad, NaN when no sector is free */
    int free_sectors, num_valleys;
    bool target_dir_free;
    /* state carried between steps */
    bool binary_histogram[VFH_MAX_SECTORS]; /* true = occupied; hysteresis memory */
    double previous_direction;              /* rad; NaN after a step with nothing free */
    /* derived at initialisation, scratch reused every step */
    double sector_midpoints[VFH_MAX_SECTORS]; /* rad */
    double sector_cos[VFH_MAX_SECTORS], sector_sin[VFH_MAX_SECTORS];
    double sector_width;                      /* rad */
    /* Reading angles wrapped to [-pi, pi] with their cosine and sine, recomputed only when an
     * angle input changes (a lidar's angles rarely do), so a step needs no trigonometry. */
    bool angles_changed;
    double reading_angle[VFH_MAX_READINGS], reading_cos[VFH_MAX_READINGS], reading_sin[VFH_MAX_READINGS];
    double reading_position[VFH_MAX_READINGS]; /* (angle - first mid-point) in sector widths */
    /* The ranges the valid readings, the densities, the binary and masked histograms and the
     * valleys' candidates were last built from (when `histograms_built`): a step whose ranges,
     * angles and parameters are those builds the same again (the hysteresis of the binary
     * histogram applied twice to the same densities changes nothing), so it keeps them; a scan
     * that holds for ten steps is built once. */
    bool histograms_built;
    double built_ranges[VFH_MAX_READINGS];
    double obstacle_density[VFH_MAX_SECTORS];
    /* Density changes from sector k-1 to k in fixed point (exact sums, O(1) per reading). */
    long long density_change[VFH_MAX_SECTORS + 1];
    double density_scale; /* fixed-point units per unit of weight */
    int valid_readings[VFH_MAX_READINGS]; /* indices of the readings inside the distance limits */
    int valid_count;
    bool masked_histogram[VFH_MAX_SECTORS];   /* true = blocked */
    double candidates[VFH_MAX_CANDIDATES];
    double candidate_costs[VFH_MAX_CANDIDATES];
    /* The first `valley_candidates` candidates come from the masked histogram's valleys and, with
     * whether each is free, are built with the histograms (and kept with them). */
    int valley_candidates;
    bool candidate_free[VFH_MAX_CANDIDATES];
};

#endif
