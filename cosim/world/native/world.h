/* What world.c shares with fleet.c (a library of its own, loaded by a fleet only): the position
 * checks' struct and reasons, and the two functions of world.c that fleet.c calls through the
 * addresses cosim.world.kernels registers with it (`fleet_use_world`). */
#ifndef COSIM_WORLD_WORLD_H
#define COSIM_WORLD_WORLD_H

#include <stdint.h>

typedef struct World World; /* a static world's grid and shapes (world.c) */
typedef struct Lidar Lidar; /* a lidar's grid, beams, shapes, scratch and output (world.c) */

typedef struct {
    const World *world;        /* the grid and shapes of a static world (`WorldDistance`) */
    const double *centre_field; /* rows x cols: each cell centre's distance [m] to the nearest occupied centre */
    const double *bounds;      /* n_bounds x 3: bounding circles of the polygons, cx, cy, r */
    int64_t n_bounds;
    double radius, goal_x, goal_y, tolerance, speed;
    /* The monitor's state, read and written back: the last position, the distance driven, the
     * minimum clearance and the anchor of the lower bound (x, y, t, bound). */
    double last_x, last_y, distance, min_clearance;
    double anchor_x, anchor_y, anchor_t, anchor_bound;
    int64_t reason;       /* why the last call stopped: CHECK_* */
    const double *points; /* 3 x capacity: the steps' x, then y, then t (end of the step [s]) */
    int64_t capacity;
} Monitor;

enum { CHECK_GOING = 0, CHECK_COLLISION = 1, CHECK_GOAL = 2, CHECK_PYTHON = 3 };

int64_t world_check_positions(Monitor *m, int64_t n);
void lidar_scan(const Lidar *s, double x, double y, double theta);

#endif
