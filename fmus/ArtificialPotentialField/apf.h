/* The artificial potential field (Khatib 1986) on a lidar scan, free of FMI. */
#ifndef APF_H
#define APF_H

#include "angles.h"
#include "config.h"
#include "model.h"

/* One evaluation of the current inputs: writes steering_dir, force_x/y, nearest_distance,
 * repelling_readings, direction_status and target_dir_free. No state is carried between calls. */
void apf_step(ModelData *data);

#endif
