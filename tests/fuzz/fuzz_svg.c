/* libFuzzer target: the SVG curve parser. */
#define FUZZ_SVG 1
#include "fuzz_curves.h"
