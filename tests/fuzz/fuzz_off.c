/* libFuzzer target: hv_mesh_read on .off files. */
#define FUZZ_EXT ".off"
#include "fuzz_mesh.h"
