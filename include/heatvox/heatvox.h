/* heatvox: heat-method distance fields and extensions on volumetric grids.
 * The umbrella header; each module has its own header under heatvox/. */
#ifndef HEATVOX_H
#define HEATVOX_H

#include "heatvox/core.h"
#include "heatvox/grid.h"
#include "heatvox/ops.h"
#include "heatvox/solve.h"
#include "heatvox/opencl.h"
#include "heatvox/mesh.h"
#include "heatvox/io.h"
#include "heatvox/vdb.h"
#include "heatvox/sdf.h"
#include "heatvox/image.h"
#include "heatvox/curves.h"
#include "heatvox/sdf2d.h"
#include "heatvox/heat.h"
#include "heatvox/petsc.h"

#endif
