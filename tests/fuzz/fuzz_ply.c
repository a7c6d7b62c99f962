/* libFuzzer target: hv_mesh_read on .ply files. */
#define FUZZ_EXT ".ply"
#include "fuzz_mesh.h"
