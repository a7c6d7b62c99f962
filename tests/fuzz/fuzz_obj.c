/* libFuzzer target: hv_mesh_read on .obj files. */
#define FUZZ_EXT ".obj"
#include "fuzz_mesh.h"
