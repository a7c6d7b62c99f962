/* libFuzzer target: the curve text format parser. */
#define FUZZ_SVG 0
#include "fuzz_curves.h"
