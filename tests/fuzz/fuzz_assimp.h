/* The fuzz_assimp target's inputs: a byte that picks the extension (its
 * value modulo FZ_ASSIMP_NEXT), then the file. Shared with make_seeds.c and
 * check_fuzz_regress.c. */
#ifndef HV_FUZZ_ASSIMP_H
#define HV_FUZZ_ASSIMP_H

#include <stdint.h>

static const char *const fz_assimp_exts[] = {".gltf", ".glb", ".fbx", ".3mf", ".dae", ".x"};
#define FZ_ASSIMP_NEXT (sizeof fz_assimp_exts / sizeof fz_assimp_exts[0])

static inline const char *fz_assimp_ext(uint8_t selector)
{
    return fz_assimp_exts[selector % FZ_ASSIMP_NEXT];
}

#endif
