/* libFuzzer target: hv_mesh_read on .stl files. */
#define FUZZ_EXT ".stl"
#include "fuzz_mesh.h"
