/* The curve parsers take memory directly (hv_curves_parse); parsed curves
 * also go through the segment count and the bounds. */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    hv_curves *c = NULL;
    if (hv_curves_parse((const char *)data, size, FUZZ_SVG, "fuzz", &c) == HV_OK) {
        double lo[2], hi[2];
        hv_curves_segments(c);
        hv_curves_bounds(c, lo, hi);
    }
    hv_curves_destroy(&c);
    return 0;
}
