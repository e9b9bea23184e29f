/*
 * VFH+ as MATLAB's controllerVFH computes it:
 * polar obstacle density with the enlargement angle, binary histogram with hysteresis,
 * masked histogram with the turning circles, valley candidates and the three-weight cost.
 *
 * Speed (720 readings in a few microseconds): no trigonometry per step (the reading angles'
 * cosines and sines are cached until an angle input changes); each reading's sector range comes
 * from a polynomial guess of gamma, corrected by the exact test cos(mid - angle) >= cos(gamma),
 * which selects the same sectors as MATLAB's cross-product test; the density is summed in fixed
 * point as a change at each end of the range, so a reading costs O(1) whatever its gamma.
 *
 * Deliberate differences from MATLAB: with robot_radius + safety_distance = 0, readings beyond the
 * outer mid-points fall into the end sectors (MATLAB's histc would index sector 0 and fail);
 * MATLAB zeroes the whole density when no reading was dropped by the distance limits, which we do
 * not copy; a NaN target direction counts as 0 (straight ahead).
 */
#include "vfh.h"

#include <float.h>
#include <math.h>
#include <string.h>

/* MATLAB's tolerance for "the same" angle or cost. */
static double tolerance(void) { return sqrt(DBL_EPSILON); }

void vfh_prepare_sectors(ModelData *data) {
    const int sectors = data->num_angular_sectors;
    data->sector_width = 2.0 * M_PI / sectors;
    for (int k = 0; k < sectors; k++) {
        data->sector_midpoints[k] = -M_PI + data->sector_width * (k + 0.5);
        data->sector_cos[k] = cos(data->sector_midpoints[k]);
        data->sector_sin[k] = sin(data->sector_midpoints[k]);
    }
    /* A weight is at most distance_limit_max: 2^52 units keep 720 of them below 2^62. */
    data->density_scale = 4503599627370496.0 / data->distance_limit_max;
    data->angles_changed = true;
}

static void update_reading_angles(ModelData *data) {
    for (int i = 0; i < VFH_MAX_READINGS; i++) {
        const double angle = wrap_to_pi(data->angles[i]);
        data->reading_angle[i] = angle;
        data->reading_cos[i] = cos(angle);
        data->reading_sin[i] = sin(angle);
        data->reading_position[i] = (angle - data->sector_midpoints[0]) / data->sector_width;
    }
    data->angles_changed = false;
}

/* A reading counts when its range lies inside the distance limits (NaN fails the test). */
static bool reading_is_valid(const ModelData *data, int i) {
    double range = data->ranges[i];
    return range >= data->distance_limit_min && range <= data->distance_limit_max &&
           isfinite(data->angles[i]);
}

static int wrap_sector(int k, int sectors) { return k < 0 ? k + sectors : (k >= sectors ? k - sectors : k); }

/* floor for x > -FLOOR_OFFSET (sector positions are > -2 * VFH_MAX_SECTORS): truncation of a
 * positive number, cheaper than floor() from libm. */
#define FLOOR_OFFSET (4 * VFH_MAX_SECTORS)
static int floor_to_int(double x) { return (int)(x + FLOOR_OFFSET) - FLOOR_OFFSET; }

/* asin within 7e-5 rad (Abramowitz & Stegun 4.4.45), for x in [0, 1]: a first guess of the sector
 * range, checked by the exact test where a range end lies this close to a sector mid-point. */
#define ASIN_ESTIMATE_ERROR 1e-4
static double asin_estimate(double x) {
    return M_PI / 2 - sqrt(1.0 - x) * (1.5707288 + x * (-0.2121144 + x * (0.0742610 - 0.0187293 * x)));
}

/* Sector k (any integer, wrapped) lies within the enlargement angle of reading i:
 * cos(mid_k - angle_i) >= cos(gamma), exact for gamma < pi/2. */
static bool sector_in_reach(const ModelData *data, int k, int i, double cos_enlargement) {
    const int s = wrap_sector(k, data->num_angular_sectors);
    return data->sector_cos[s] * data->reading_cos[i] + data->sector_sin[s] * data->reading_sin[i] >=
           cos_enlargement;
}

/* Add `weight` (fixed point) to sectors lowest..highest, wrapped: a change at each end. */
static void add_to_sectors(long long *change, int lowest, int highest, int sectors, long long weight) {
    const int first = wrap_sector(lowest, sectors), last = wrap_sector(highest, sectors);
    change[first] += weight;
    change[last + 1] -= weight;
    if (first > last) change[0] += weight; /* the range crosses +-pi */
}

static void collect_valid_readings(ModelData *data) {
    int count = 0;
    for (int i = 0; i < VFH_MAX_READINGS; i++)
        if (reading_is_valid(data, i)) data->valid_readings[count++] = i;
    data->valid_count = count;
}

/* Integer bound of the enlargement range of reading i: the exact test decides only when the guess
 * `edge` (in sector widths) lies within the estimate's error of a sector mid-point; that error
 * (< 1e-4 rad) is far below a sector (>= 8.7e-3 rad), so the bound moves by one at most. */
static int exact_lowest(const ModelData *data, double edge, double margin, int i, double cos_enlargement) {
    int lowest = floor_to_int(edge) + 1;
    const double fraction = edge - (lowest - 1);
    if (fraction < margin || fraction > 1.0 - margin) {
        if (sector_in_reach(data, lowest - 1, i, cos_enlargement)) lowest--;
        else if (!sector_in_reach(data, lowest, i, cos_enlargement)) lowest++;
    }
    return lowest;
}

static int exact_highest(const ModelData *data, double edge, double margin, int i, double cos_enlargement) {
    int highest = floor_to_int(edge);
    const double fraction = edge - highest;
    if (fraction < margin || fraction > 1.0 - margin) {
        if (sector_in_reach(data, highest + 1, i, cos_enlargement)) highest++;
        else if (!sector_in_reach(data, highest, i, cos_enlargement)) highest--;
    }
    return highest;
}

/* Eqs (4)-(6) of VFH+: each reading adds a - d to every sector whose mid-point lies within the
 * enlargement angle gamma = asin((R + d_safe) / d) of its direction. */
static void build_obstacle_density(ModelData *data) {
    const int sectors = data->num_angular_sectors;
    const double per_width = 1.0 / data->sector_width;
    const double enlargement_radius = data->robot_radius + data->safety_distance;
    const double margin = ASIN_ESTIMATE_ERROR * per_width;
    long long *change = data->density_change;
    for (int k = 0; k <= sectors; k++) change[k] = 0;
    for (int v = 0; v < data->valid_count; v++) {
        const int i = data->valid_readings[v];
        const double range = data->ranges[i];
        const long long weight = (long long)((data->distance_limit_max - range) * data->density_scale + 0.5);
        const double position = data->reading_position[i];
        if (sectors == 1) {
            add_to_sectors(change, 0, 0, sectors, weight);
        } else if (enlargement_radius == 0.0) {
            /* histc on the mid-points: sector k covers [mid_k, mid_k+1). */
            int k = floor_to_int(position);
            k = k < 0 ? 0 : (k >= sectors ? sectors - 1 : k);
            add_to_sectors(change, k, k, sectors, weight);
        } else {
            double sine = enlargement_radius / range;
            if (sine >= 1.0) sine = 1.0 - DBL_EPSILON; /* inside the robot: just under pi/2 */
            const double cos_enlargement = sqrt(1.0 - sine * sine);
            const double reach = asin_estimate(sine) * per_width;
            const int lowest = exact_lowest(data, position - reach, margin, i, cos_enlargement);
            const int highest = exact_highest(data, position + reach, margin, i, cos_enlargement);
            if (lowest <= highest) add_to_sectors(change, lowest, highest, sectors, weight);
        }
    }
    long long sum = 0;
    for (int k = 0; k < sectors; k++) {
        sum += change[k];
        data->obstacle_density[k] = (double)sum / data->density_scale;
    }
}

/* Eq (7): above the high threshold occupied, below the low one free, in between unchanged. */
static void build_binary_histogram(ModelData *data) {
    for (int k = 0; k < data->num_angular_sectors; k++) {
        if (data->obstacle_density[k] > data->histogram_threshold_high) data->binary_histogram[k] = true;
        else if (data->obstacle_density[k] < data->histogram_threshold_low) data->binary_histogram[k] = false;
    }
}

/* Eqs (8)-(11): a reading inside the right (left) turning circle, enlarged by R + d_safe, blocks
 * every direction right (left) of it. The circles are centred at (0, -/+ r_min). */
static void build_masked_histogram(ModelData *data) {
    const int sectors = data->num_angular_sectors;
    const double *midpoints = data->sector_midpoints;
    const double turning_radius = data->min_turning_radius;
    const double blocking_radius = turning_radius + data->robot_radius + data->safety_distance;
    bool right_blocked = false, left_blocked = false;
    double limit_right = midpoints[0], limit_left = midpoints[sectors - 1];
    for (int v = 0; v < data->valid_count; v++) {
        const int i = data->valid_readings[v];
        const double range = data->ranges[i];
        /* |reading - centre| >= range - r_min, so far readings cannot block: skip the sine. */
        if (range - turning_radius >= blocking_radius) continue;
        const double angle = data->reading_angle[i];
        /* Squared distance to the centre (0, -/+ r): d^2 + r^2 +/- 2 r d sin(angle). */
        const double common = range * range + turning_radius * turning_radius;
        const double cross = 2.0 * turning_radius * range * data->reading_sin[i];
        const double blocking_squared = blocking_radius * blocking_radius;
        if (angle <= 0.0 && common + cross < blocking_squared) {
            limit_right = angle; /* the last right-blocking reading in scan order */
            right_blocked = true;
        }
        if (angle >= 0.0 && !left_blocked && common - cross < blocking_squared) {
            limit_left = angle; /* the first left-blocking reading in scan order */
            left_blocked = true;
        }
    }
    /* A blocking reading inside an end sector closes that sector too. */
    const int second = sectors > 1 ? 1 : 0;
    if (right_blocked && limit_right <= midpoints[0]) limit_right = midpoints[second];
    if (left_blocked && limit_left >= midpoints[sectors - 1]) limit_left = midpoints[sectors - 1 - second];
    for (int k = 0; k < sectors; k++)
        data->masked_histogram[k] = data->binary_histogram[k] || midpoints[k] < limit_right ||
                                    midpoints[k] > limit_left;
}

/* A direction is free when its nearest sector is free (both sectors when it lies on a border). */
static bool direction_is_free(const ModelData *data, double direction) {
    const int sectors = data->num_angular_sectors;
    const double position = (direction - data->sector_midpoints[0]) / data->sector_width;
    const double below = floor(position), fraction = position - below;
    const int lower = wrap_sector((int)below % sectors, sectors), upper = wrap_sector(lower + 1, sectors);
    if (fabs(1.0 - 2.0 * fraction) * data->sector_width < tolerance())
        return !data->masked_histogram[lower] && !data->masked_histogram[upper];
    return !data->masked_histogram[fraction < 0.5 ? lower : upper];
}

/* Eq (15), with MATLAB's scale factor (mu1 + mu2 + mu3) / 3, which does not change the winner. */
static double direction_cost(const ModelData *data, double candidate, double target, double previous) {
    const double total = data->target_direction_weight + data->current_direction_weight +
                         data->previous_direction_weight;
    const double weighted = data->target_direction_weight * fabs(wrap_to_pi(target - candidate)) +
                            data->current_direction_weight * fabs(wrap_to_pi(0.0 - candidate)) +
                            data->previous_direction_weight * fabs(wrap_to_pi(previous - candidate));
    return weighted / 3.0 * total;
}

/* Eqs (12)-(14): candidates from the valleys of the masked histogram (not circular), with whether
 * each is free; how many in valley_candidates, the valleys and free sectors in the outputs. */
static void collect_valley_candidates(ModelData *data) {
    const int sectors = data->num_angular_sectors;
    const double *midpoints = data->sector_midpoints;
    const double half_opening = data->narrow_opening_threshold / 2.0;
    int count = 0, valleys = 0, free_sectors = 0;
    for (int start = 0; start < sectors;) {
        if (data->masked_histogram[start]) { start++; continue; }
        int end = start;
        while (end + 1 < sectors && !data->masked_histogram[end + 1]) end++;
        valleys++;
        free_sectors += end - start + 1;
        if (data->sector_width * (end - start) < data->narrow_opening_threshold) {
            data->candidates[count++] = 0.5 * (midpoints[start] + midpoints[end]);
        } else {
            data->candidates[count++] = midpoints[start] + half_opening;
            data->candidates[count++] = midpoints[end] - half_opening;
        }
        start = end + 1;
    }
    for (int c = 0; c < count; c++) data->candidate_free[c] = direction_is_free(data, data->candidates[c]);
    data->valley_candidates = count;
    data->num_valleys = valleys;
    data->free_sectors = free_sectors;
}

/* The valleys' candidates, then the target, the current (0) and the previous direction, with
 * whether each is free. Returns how many. */
static int collect_candidates(ModelData *data, double target, double previous) {
    int count = data->valley_candidates;
    data->candidates[count++] = target;
    data->candidates[count++] = 0.0;
    data->candidates[count++] = previous;
    for (int c = data->valley_candidates; c < count; c++)
        data->candidate_free[c] = direction_is_free(data, data->candidates[c]);
    return count;
}

void vfh_step(ModelData *data) {
    if (data->angles_changed) {
        update_reading_angles(data);
        data->histograms_built = false;
    }
    /* Bit for bit the ranges of the last build (config.h: `histograms_built`): the same histograms. */
    if (!data->histograms_built || memcmp(data->ranges, data->built_ranges, sizeof data->ranges) != 0) {
        collect_valid_readings(data);
        build_obstacle_density(data);
        build_binary_histogram(data);
        build_masked_histogram(data);
        collect_valley_candidates(data);
        memcpy(data->built_ranges, data->ranges, sizeof data->ranges);
        data->histograms_built = true;
    }

    const double target = isnan(data->target_dir) ? 0.0 : wrap_to_pi(data->target_dir);
    const double previous = isnan(data->previous_direction) ? 0.0 : data->previous_direction;
    const int count = collect_candidates(data, target, previous);
    data->target_dir_free = data->free_sectors > 0 && data->candidate_free[count - 3];
    if (data->free_sectors == 0) {
        data->steering_dir = data->previous_direction = NAN;
        return;
    }

    double lowest_cost = INFINITY;
    for (int c = 0; c < count; c++) {
        double cost = INFINITY;
        if (data->candidate_free[c])
            cost = direction_cost(data, data->candidates[c], target, previous);
        data->candidate_costs[c] = cost;
        if (cost < lowest_cost) lowest_cost = cost;
    }
    /* Among (nearly) equal costs the smallest angle wins. */
    double steering = NAN;
    for (int c = 0; c < count; c++) {
        if (!(data->candidate_costs[c] - lowest_cost < tolerance())) continue;
        if (isnan(steering) || data->candidates[c] < steering) steering = data->candidates[c];
    }
    data->steering_dir = data->previous_direction = steering;
}
