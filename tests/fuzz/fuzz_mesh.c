/* libFuzzer target: hv_mesh_read on a file without extension, so that the
 * format is chosen by content (binary STL size, "ply", OFF keywords, "solid",
 * OBJ records). */
#define FUZZ_EXT ""
#include "fuzz_mesh.h"
