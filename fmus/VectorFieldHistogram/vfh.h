/* VFH+ (Ulrich & Borenstein 1998) in the variant of MATLAB's controllerVFH, free of FMI. */
#ifndef VFH_H
#define VFH_H

#include "angles.h"
#include "config.h"
#include "model.h"

/* Sector mid-points linspace(-pi + pi/N, pi - pi/N, N); call once the parameters are fixed. */
void vfh_prepare_sectors(ModelData *data);

/* One VFH+ evaluation of the current inputs: updates the binary histogram and the previous
 * direction in `data` and writes steering_dir, free_sectors, num_valleys, target_dir_free. */
void vfh_step(ModelData *data);

#endif
