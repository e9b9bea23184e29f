/* The pure-pursuit algorithm of MATLAB's controllerPurePursuit, free of FMI. */
#ifndef PURE_PURSUIT_H
#define PURE_PURSUIT_H

#include "angles.h"
#include "config.h"
#include "model.h"

/* Copy the rows of the waypoint input that hold no NaN into data->path_*, in order. */
void pure_pursuit_compact_path(ModelData *data);

/* Move the projection point forward along data->path_* for the pose (data->x, data->y) and
 * return the lookahead point: arc length lookahead_distance ahead of the projection point, or the
 * last waypoint when the path ends first. Needs path_count >= 1. */
void pure_pursuit_lookahead(const ModelData *data, ProjectionState *projection, double *lookahead_x,
                            double *lookahead_y);

/* Angular velocity [rad/s] for the bearing alpha [rad] of the lookahead point. */
double pure_pursuit_angular_velocity(const ModelData *data, double alpha);

#endif
