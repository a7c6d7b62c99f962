/*
 * OpenVDB files, behind a C API.
 *
 * Index convention: voxel (i,j,k) of an hv_grid is OpenVDB index (i,j,k), and
 * the grid's linear transform has voxel size h and maps that index to the cell
 * centre origin + (i+1/2, j+1/2, k+1/2) * h (OpenVDB indices are voxel centres).
 * A 2D grid (dim 2) is written as the slab k = 0. Grids read back are dim 3
 * (n[2] may be 1).
 *
 * Level sets follow OpenVDB's conventions: class "level set", background = half
 * band width in world units (positive), negative inside, inactive voxels hold
 * -background inside and +background outside.
 *
 * Writers follow the library's safe-output rule (temporary name, then rename).
 * All functions are thread-compatible (no shared mutable state besides
 * OpenVDB's one-time initialization); errors are reported as hv_status with a
 * message naming the file and grid (hv_last_error()).
 */
#ifndef HEATVOX_VDB_H
#define HEATVOX_VDB_H

#include "grid.h"

/* mesh.h's mesh, for hv_grid_to_mesh below (vdb.h sits below mesh.h). */
typedef struct hv_mesh hv_mesh;

#ifdef __cplusplus
extern "C" {
#endif

/* Grid classes, equal to openvdb::GridClass. */
typedef enum hv_vdb_class {
    HV_VDB_UNKNOWN = 0,
    HV_VDB_LEVEL_SET = 1,
    HV_VDB_FOG_VOLUME = 2,
    HV_VDB_STAGGERED = 3
} hv_vdb_class;

/* ---- Writing ------------------------------------------------------------ */

/* A writer collects grids (copied when added) and file metadata, then writes
 * them all into one .vdb file. */
typedef struct hv_vdb_writer hv_vdb_writer;

/* Creates an empty writer. The caller owns *out (hv_vdb_writer_destroy). */
HV_API hv_status hv_vdb_writer_create(hv_vdb_writer **out);

/* Frees the writer and its grids, sets *w to NULL. Accepts NULL and *w == NULL. */
HV_API void hv_vdb_writer_destroy(hv_vdb_writer **w);

/* Adds a signed distance field as a float grid of class level set.
 * background = band_voxels * h (must be > 0). With dense == 0 only voxels with
 * |phi| < background are active; the other voxels are inactive and hold
 * -background where phi < 0 and +background elsewhere. With dense != 0 every
 * voxel of the block is active with its own value. Names must be unique and
 * non-empty. The grid is copied: g may be freed after the call. */
HV_API hv_status hv_vdb_writer_add_levelset(hv_vdb_writer *w, const hv_grid *g, const char *name,
                                            double band_voxels, int dense);

/* Adds a narrow-band level set from tiles (hv_sdf_compute_tiles): voxels
 * active in t with |value| < band_voxels * h are active; every other voxel
 * and tile takes -background or +background by OpenVDB's signed flood fill
 * from the active voxels. No dense grid is made. The tiles are copied. */
HV_API hv_status hv_vdb_writer_add_levelset_tiles(hv_vdb_writer *w, const hv_tiles *t,
                                                  const char *name, double band_voxels);
/* What a level set taken from a tile sink cost (hv_vdb_writer_levelset_sink). */
typedef struct hv_vdb_sink_stats {
    size_t batches, tiles;   /* put calls, tiles they held */
    size_t leaves;           /* the tree's leaves */
    double tree_bytes;       /* the tree's memory once whole (OpenVDB's memUsage) */
    size_t packed_leaves;    /* leaves kept as their compressed bytes alone */
    double packed_bytes;     /* the memory of those bytes */
    double tree_bytes_bound; /* what begin allowed for: tree and bytes */
    double t_leaves;         /* seconds building (and packing) leaves, within the producer's run */
    double t_fill;           /* seconds of the signed flood fill at the end */
} hv_vdb_sink_stats;

/* The narrow band of hv_vdb_writer_add_levelset_tiles from tiles handed over
 * in batches as a producer finishes them (hv_sdf_stream_tiles): *out is a
 * sink whose put turns each batch into the tree's leaves at once (the batch
 * is not kept), and whose end (ok) runs the signed flood fill and adds the
 * grid under name. The result is the grid add_levelset_tiles makes of all
 * the tiles at once, voxel for voxel. When the block sits on the writer's
 * 8^3 leaf lattice (always without an index origin) each leaf is packed as
 * put makes it, on all cores: compressed to the bytes the file will hold
 * and its values freed, about 1 kB a leaf at 3 voxels each side against
 * 2.2 kB. begin refuses with HV_ERR_NOMEM and the figure when its bound on
 * the tiles times a leaf's estimated memory exceeds this machine's memory.
 * stats (may be NULL) is filled at end and must live until then. One sink
 * at a time per writer (another is refused until the first has ended); the
 * writer must outlive it. */
HV_API hv_status hv_vdb_writer_levelset_sink(hv_vdb_writer *w, const char *name, double band_voxels,
                                             hv_vdb_sink_stats *stats, hv_tiles_sink *out);

/* Adds the inside of a signed distance field (negative inside) as a float grid
 * of class fog volume, the form renderers and Blender's volumes shade:
 * clamp(1/2 - phi / h, 0, 1), so 1 inside, 0 outside and a ramp one voxel
 * wide across the zero level; the voxels above 0 are active (the inside's
 * constant leaves become active tiles), the rest inactive, background 0. The
 * grid is copied. */
HV_API hv_status hv_vdb_writer_add_fog(hv_vdb_writer *w, const hv_grid *g, const char *name);

/* Adds a scalar float grid of class unknown, every voxel active, background 0. */
HV_API hv_status hv_vdb_writer_add_float(hv_vdb_writer *w, const hv_grid *g, const char *name);

/* Adds a Vec3s grid (e.g. a velocity or gradient field) from three component
 * grids of equal size, voxel size and origin; every voxel active, background 0.
 * Vector type VEC_CONTRAVARIANT_RELATIVE: values are in world units and scale
 * with the transform but do not translate (right for velocities/displacements;
 * with heatvox's axis-aligned uniform transforms no value ever changes). */
HV_API hv_status hv_vdb_writer_add_vec3(hv_vdb_writer *w, const hv_grid *gx, const hv_grid *gy,
                                        const hv_grid *gz, const char *name);

/* Adds a float grid (t) or a vec3s grid (tx, ty, tz: the same tiles in the
 * same order, else HV_ERR_INVALID_ARG) of the tiles' active voxels only (for
 * vec3s, those of tx), class unknown, background 0: inactive voxels are not
 * stored. Placed like hv_vdb_writer_add_float's grid of the same block
 * (transform, index offset, block metadata). A NaN or Inf on an active voxel
 * is HV_ERR_NUMERIC naming the grid. The tiles are copied. */
HV_API hv_status hv_vdb_writer_add_float_tiles(hv_vdb_writer *w, const hv_tiles *t,
                                               const char *name);
HV_API hv_status hv_vdb_writer_add_vec3_tiles(hv_vdb_writer *w, const hv_tiles *tx,
                                              const hv_tiles *ty, const hv_tiles *tz,
                                              const char *name);

/* Adds a bool grid active (and true) where g->solid is non-zero (g->v is
 * ignored); an all-fluid grid, or one without a mask, gives an empty grid. */
HV_API hv_status hv_vdb_writer_add_mask(hv_vdb_writer *w, const hv_grid *g, const char *name);

/* Makes every grid added afterwards share one index space whose index (0,0,0)
 * sits at world position index0_world (a voxel centre), e.g. the
 * index0_world of a grid that was read (hv_vdb_grid_info), so that the output
 * has the input's transform and its voxels keep their index coordinates. A
 * grid is then written at index offset round((origin + h/2 - index0_world)/h),
 * which must be whole voxels (within 1e-4) or the add fails naming the grid.
 * Without this call, index (0,0,0) is each grid's first voxel. */
HV_API hv_status hv_vdb_writer_set_index_origin(hv_vdb_writer *w, const double index0_world[3]);

/* Sets a string metadata entry of the file (e.g. "source", "parameters").
 * The writer adds "creator" = "heatvox <version>" by itself. */
HV_API hv_status hv_vdb_writer_set_meta(hv_vdb_writer *w, const char *key, const char *value);

/* Sets a string metadata entry on a grid already added under grid_name. */
HV_API hv_status hv_vdb_writer_set_grid_meta(hv_vdb_writer *w, const char *grid_name,
                                             const char *key, const char *value);

/* Writes every grid added so far to path (Blosc compression with active-mask
 * compression, floats stored as 32 bit; level sets from tiles compress their
 * leaves on all cores), through a temporary file in the same
 * directory that is renamed into place only when complete. The writer stays
 * usable (it can write again). Fails with HV_ERR_INVALID_ARG when no grid was
 * added, HV_ERR_IO when the file cannot be written (no temporary is left). */
HV_API hv_status hv_vdb_writer_write(hv_vdb_writer *w, const char *path);

/* ---- Reading ------------------------------------------------------------ */

/* Description of one grid in a file. */
typedef struct hv_vdb_grid_info {
    char name[256];         /* truncated if longer */
    char value_type[32];    /* OpenVDB's value type name: "float", "double", "vec3s", "bool", ... */
    int grid_class;         /* hv_vdb_class */
    int uniform;            /* 1: linear, axis-aligned, uniform scale (readable by heatvox) */
    double voxel_size[3];   /* world units per index step along each index axis */
    double index0_world[3]; /* world position of index (0,0,0), a voxel centre */
    int64_t active_voxels;  /* number of active voxels (tiles counted by their voxels) */
    int bbox_lo[3];         /* active voxel bounding box, inclusive; lo > hi when empty */
    int bbox_hi[3];
} hv_vdb_grid_info;

/* Lists the grids of a file. Fills up to cap entries of info (info may be NULL
 * when cap is 0) and sets *count to the number of grids in the file.
 * Missing or unreadable file: HV_ERR_IO naming the file. */
HV_API hv_status hv_vdb_list(const char *path, hv_vdb_grid_info *info, size_t cap, size_t *count);

/* Which index box a read copies into a dense grid. Pass NULL for the default:
 * the block recorded by heatvox's writer (grid metadata heatvox_block_min and
 * heatvox_block_max), else the grid's active voxel bounding box (an error for a
 * grid without active voxels). With use_box != 0, the inclusive index box
 * [box_lo, box_hi]; voxels outside the grid's data read as its background
 * (with the level set's sign where the tree stores one). */
typedef struct hv_vdb_read_opts {
    int use_box;
    int box_lo[3];
    int box_hi[3];
} hv_vdb_read_opts;

/* Reads a float or double grid into a new dense grid (float); inactive voxels
 * take their stored value (for level sets: -background inside, +background
 * outside). h and origin come from the transform, which must be linear,
 * axis-aligned and uniform. grid_class may be NULL; it receives hv_vdb_class.
 * Missing grid: HV_ERR_INVALID_ARG naming the grid and file and listing the
 * grids present. Wrong value type: HV_ERR_INVALID_ARG. The caller owns *out. */
HV_API hv_status hv_vdb_read_float(const char *path, const char *name, const hv_vdb_read_opts *opts,
                                   hv_grid **out, int *grid_class);

/* Reads a float or double grid as 8^3 tiles of the block [lo, hi] (index
 * coordinates, inclusive, as hv_vdb_common_box gives them), without a dense
 * grid: the tiles (corners at lo + multiples of 8) that hold an active voxel
 * of the grid inside the block (every voxel of an active tile of the tree
 * counts), in order of k, then j, then i, with every cell's value (inactive
 * cells: the value the tree stores there, for level sets the signed
 * background) and the active voxels (those inside the block). n, h and
 * origin are those of the grid hv_vdb_read_float would make of the same
 * block. Errors as hv_vdb_read_float's. The caller owns *out
 * (hv_tiles_destroy). */
HV_API hv_status hv_vdb_read_float_tiles(const char *path, const char *name, const int lo[3],
                                         const int hi[3], hv_tiles **out, int *grid_class);

/* Reads grid `name` (float or double: *ncomp = 1; vec3s or vec3d: 3) at every
 * cell of like's tiles, which must come from the same file's lattice
 * (hv_vdb_read_float_tiles): out[c] receive like's tiles, in like's order,
 * the grid's values (its background where it stores none) and its own active
 * voxels. Transforms must agree (HV_ERR_INVALID_ARG naming the grid). The
 * caller owns out[0 .. *ncomp - 1]. */
HV_API hv_status hv_vdb_read_tiles_like(const char *path, const char *name, const hv_tiles *like,
                                        hv_tiles *out[3], int *ncomp);

/* Reads a vec3s or vec3d grid into three new dense component grids. */
HV_API hv_status hv_vdb_read_vec3(const char *path, const char *name, const hv_vdb_read_opts *opts,
                                  hv_grid **gx, hv_grid **gy, hv_grid **gz);

/* Reads an obstacle mask into a new grid with a solid mask: v = 1 and solid = 1
 * where solid, 0 elsewhere. Bool and mask grids: solid where the voxel is
 * active or true. Float/double level sets: solid where the value is < 0.
 * Other float/double grids: solid where the value is non-zero. */
HV_API hv_status hv_vdb_read_mask(const char *path, const char *name, const hv_vdb_read_opts *opts,
                                  hv_grid **out);

/* Computes one index box for reading several grids of a file onto the same
 * dense block: the union of their default boxes (see hv_vdb_read_opts).
 * Fails with HV_ERR_INVALID_ARG naming both grids when their transforms differ
 * (voxel size or translation), or naming a missing grid. */
HV_API hv_status hv_vdb_common_box(const char *path, const char *const *names, size_t count,
                                   int lo[3], int hi[3]);

/* Copies a metadata entry (file metadata when grid_name is NULL, else the
 * grid's) as text into buf. Missing key: HV_ERR_INVALID_ARG naming it. */
HV_API hv_status hv_vdb_read_meta(const char *path, const char *grid_name, const char *key,
                                  char *buf, size_t bufsize);

/* ---- Mesh extraction ---------------------------------------------------- */
/* Extracts the isosurface {value == isovalue} of a 3D grid (a signed distance
 * field: negative inside) as a closed, manifold, consistently oriented
 * triangle mesh (outward normals, positive signed volume), with OpenVDB's
 * tools::volumeToMesh; its quads are split into triangles along their shorter
 * diagonal. Cells outside the block count as outside, so a surface that
 * reaches the block's walls is closed there by caps on the walls (the outer
 * faces of the boundary cells); a grid entirely below isovalue gives the
 * block's box. Vertices lie on the zero set of the grid's trilinear
 * interpolant (Newton steps from OpenVDB's points, at most half a voxel), and
 * every vertex has its own position (readers that weld by position, in double
 * or in float32, keep the topology).
 * adaptivity in [0, 1]: 0 keeps one vertex per crossed voxel (more where a
 * voxel is crossed by several sheets); larger values merge regions of up to
 * 8^3 voxels whose normals differ by 1 - cos(angle) <= adaptivity into fewer,
 * larger triangles, but no merged triangle strays more than half a voxel from
 * the isosurface (checked on the trilinear field at points at most a voxel
 * apart; regions that do are split again). Vertices are in world coordinates
 * (the grid's origin and h). Errors: HV_ERR_INVALID_ARG for a grid that is not
 * 3D, adaptivity outside [0, 1], a non-finite isovalue, or a grid with no value
 * below isovalue (no surface); HV_ERR_NUMERIC for NaN or Inf values. The
 * caller owns *out (hv_mesh_destroy). */
HV_API hv_status hv_grid_to_mesh(const hv_grid *g, double isovalue, double adaptivity,
                                 hv_mesh **out);

#ifdef __cplusplus
}
#endif
#endif
