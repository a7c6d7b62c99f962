/* Private pieces of the 2D signed heat method (sdf2d.c), for the tests. */
#ifndef HV_HEAT_SDF2D_INTERNAL_H
#define HV_HEAT_SDF2D_INTERNAL_H

/* 1: the repair tests every loop against every other for nesting, without the
 * spatial index (the quadratic reference the index must agree with bit for
 * bit). 0 by default; tests only, not thread-safe to change during a run. */
extern int hv_sdf2d_all_pairs;

#endif
