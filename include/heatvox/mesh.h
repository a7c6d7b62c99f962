/*
 * Triangle meshes: readers for OBJ, PLY (ascii, binary little/big endian), STL
 * (ascii, binary) and OFF; polygons are fanned into triangles and vertices are
 * welded by exact position. A defect report describes what is broken.
 *
 * Generators (icosphere, torus) and defect makers (holes, flips, duplicates,
 * soups) build known-truth test cases; they never touch files.
 */
#ifndef HEATVOX_MESH_H
#define HEATVOX_MESH_H

#include "core.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct hv_mesh {
    size_t nverts;
    size_t ntris;
    double *verts;  /* 3 * nverts coordinates, owned */
    uint32_t *tris; /* 3 * ntris vertex indices, owned */
    /* What the reader did (0 / NULL for meshes not read from a file). */
    const char *format;           /* static name, e.g. "PLY binary_little_endian" */
    size_t input_vertices;        /* vertices in the input, before welding */
    size_t unreferenced_vertices; /* input vertices no face used; dropped */
    size_t polygons_fanned;       /* input faces with more than 3 corners */
    /* Where the first vertex with a NaN or Inf coordinate stands in the file:
     * its 1-based place in the file's vertex list (0: none), and the line of a
     * text format (0: a binary format, or none). */
    size_t nonfinite_vertex;
    size_t nonfinite_line;
    /* Metres per coordinate unit, from the file (0: it declares none, or
     * the format has no unit). heatvox never rescales coordinates: FBX gives
     * its GlobalSettings UnitScaleFactor (0.01: centimetres), glTF is metres
     * by definition, and COLLADA comes in metres because assimp applies the
     * file's <unit> to the scene's root. */
    double unit_meters;
    /* Point and line primitives left out (formats read through assimp). */
    size_t skipped_primitives;
} hv_mesh;

typedef struct hv_mesh_report {
    size_t vertices;           /* after welding */
    size_t triangles;          /* after fanning */
    size_t polygons_fanned;    /* input faces with more than 3 corners */
    size_t boundary_edges;     /* edges used by exactly one triangle */
    size_t nonmanifold_edges;  /* edges used by more than two triangles */
    size_t inconsistent_edges; /* manifold edges whose two triangles traverse it the same way */
    size_t duplicate_faces;    /* triangles repeating the vertex set of an earlier one */
    size_t degenerate_faces;   /* repeated vertex index or zero area */
    size_t nonfinite_vertices; /* NaN or Inf coordinates */
    size_t components;         /* edge-connected components of triangles */
    /* Added fields. */
    size_t edges;                 /* distinct undirected edges */
    size_t vertex_components;     /* components joined through shared vertices (an hourglass
                                   touching at one vertex is 1 here, 2 in components) */
    size_t input_vertices;        /* copied from the mesh (0 when not read from a file) */
    size_t unreferenced_vertices; /* copied from the mesh */
    double signed_volume;         /* sum of det(a,b,c)/6 over finite triangles: > 0 when a
                                   closed mesh is oriented outward */
} hv_mesh_report;

/* Reads a mesh, choosing the format by extension (.obj .ply .stl .off, any case)
 * and falling back to the content. Through assimp (by extension only): glTF
 * 2.0 (.gltf with its buffers beside it, .glb), FBX, 3MF, COLLADA (.dae) and
 * DirectX (.x); their scene graphs are flattened with the nodes' transforms
 * (faces turned back where a transform mirrors), polygons fanned, points and
 * lines left out and counted, and a file assimp rejects gives HV_ERR_PARSE
 * naming it with assimp's reason. Errors name the file and the line or byte
 * offset. An empty mesh (no triangles) is an error. The caller owns *out.
 * Vertices that no face uses are dropped (counted in unreferenced_vertices).
 * A PLY `tristrips` element (lists with -1 restarts) is converted to triangles
 * with alternating winding; strip triangles repeating a vertex (the stitching
 * between strips) are dropped. Faces with fewer than 3 corners are an error.
 * Only regular files and pipes (up to 1 GiB) are read; finite coordinates
 * beyond +-1e100 give HV_ERR_NUMERIC (NaN and inf load and are counted). */
HV_API hv_status hv_mesh_read(const char *path, hv_mesh **out);

/* The format hv_mesh_read reads a file of this name in, judging by the
 * extension alone (any case): "OBJ", "PLY", "STL", "OFF", or one of those read
 * through assimp ("glTF 2.0 via assimp", "FBX via assimp", ...); NULL for an
 * extension it does not know (hv_mesh_read then judges by the content).
 * The string is static. */
HV_API const char *hv_mesh_format_by_extension(const char *path);

/* Builds a mesh from arrays (copied); vertices are welded by exact position
 * (-0 equals +0; vertices with a NaN coordinate are never merged) and vertices
 * no triangle uses are dropped. Indices must be < nverts; ntris must be > 0. */
HV_API hv_status hv_mesh_from_arrays(hv_mesh **out, const double *verts, size_t nverts,
                                     const uint32_t *tris, size_t ntris);

/* Deep copy. The caller owns *out. */
HV_API hv_status hv_mesh_clone(const hv_mesh *m, hv_mesh **out);

/* Frees *m and sets it to NULL; accepts NULL and *m == NULL. */
HV_API void hv_mesh_destroy(hv_mesh **m);

/* Point clouds (a scan, a depth fusion, a normal estimator's output):
 * positions, with unit outward normals or without (an unoriented cloud,
 * whose orientation hv_points_surface recovers). */
typedef struct hv_points {
    size_t count;
    double *xyz;        /* 3 * count coordinates, owned */
    double *normals;    /* 3 * count unit normals, owned; NULL when the cloud has none */
    const char *format; /* static name ("PLY points", "text points"); NULL when not read */
} hv_points;

/* 1 when path names a point cloud: a text file by its extension (.xyz,
 * .pts, .xyzn) or a PLY file whose header has vertices and no faces. */
HV_API int hv_points_file(const char *path);

/* Reads a point cloud: text, x y z nx ny nz or x y z per line (# starts a
 * comment; further columns are ignored; every line has a normal or none),
 * or a PLY vertex element with x y z, and nx ny nz where it has them
 * (normals NULL when not). NaN/Inf values and normals of zero length are
 * errors (named by line, or by the point's place in a binary PLY). Normals
 * are scaled to unit length. The caller owns *out (hv_points_destroy). */
HV_API hv_status hv_points_read(const char *path, hv_points **out);

/* A point cloud from arrays (copied, normals scaled to unit length; normals
 * NULL: an unoriented cloud). */
HV_API hv_status hv_points_from_arrays(hv_points **out, const double *xyz, const double *normals,
                                       size_t count);

/* Frees *p and sets it to NULL; accepts NULL and *p == NULL. */
HV_API void hv_points_destroy(hv_points **p);

/* Axis-aligned bounds of the finite vertices (HV_ERR_NUMERIC when none is finite). */
HV_API hv_status hv_mesh_bounds(const hv_mesh *m, double lo[3], double hi[3]);

/* Fills the defect report. O(n log n) in the number of triangles. Triangles that
 * repeat a vertex index are counted as degenerate and left out of the edge,
 * orientation and component counts (their "edges" are not edges). */
HV_API hv_status hv_mesh_report_compute(const hv_mesh *m, hv_mesh_report *r);

/* Writes the mesh as OBJ (temporary file then rename). Coordinates are written
 * with 17 significant digits, so reading the file back gives the same doubles. */
HV_API hv_status hv_mesh_write_obj(const hv_mesh *m, const char *path);
/* Writes the mesh as binary little-endian PLY: vertex x, y, z as double (read
 * back bit for bit), faces as "property list uchar uint vertex_indices";
 * temporary file then rename. */
HV_API hv_status hv_mesh_write_ply(const hv_mesh *m, const char *path);
/* Writes the mesh as binary STL (float32 coordinates and unit facet normals, as
 * the format has them; the zero normal for a degenerate facet), temporary file
 * then rename. STL has no shared vertices: readers weld them back by position,
 * so vertices that round to the same float32 point come back as one. */
HV_API hv_status hv_mesh_write_stl(const hv_mesh *m, const char *path);
/* Writes the mesh in the format its extension names: .obj, .ply or .stl (any
 * case). Another extension is HV_ERR_INVALID_ARG naming the path. Write
 * failures are HV_ERR_IO naming the file, and leave no file behind. */
HV_API hv_status hv_mesh_write(const hv_mesh *m, const char *path);

/* ---- Generators (pure functions; the caller owns *out) ---- */

/* Icosphere: the icosahedron subdivided `subdiv` times (0..9), 20·4^subdiv
 * triangles, vertices on the sphere of centre c and radius r, counter-clockwise
 * seen from outside (outward normals, positive signed volume). */
HV_API hv_status hv_mesh_make_sphere(hv_mesh **out, const double c[3], double r, int subdiv);

/* Torus around the z axis through c: major radius R, tube radius r (0 < r < R),
 * nu segments around z and nv around the tube (each >= 3); 2·nu·nv triangles,
 * oriented outward. */
HV_API hv_status hv_mesh_make_torus(hv_mesh **out, const double c[3], double R, double r, int nu,
                                    int nv);

/* ---- Defect makers for tests (modify m in place; deterministic for a seed) ---- */

/* Removes nholes patches: around each of nholes random vertices, every triangle
 * with a corner within radius_frac × (bounding-box diagonal) of it (at least the
 * triangles around that vertex). Unused vertices are dropped. Fails with
 * HV_ERR_INVALID_ARG if no triangle would remain. */
HV_API hv_status hv_mesh_defect_holes(hv_mesh *m, int nholes, double radius_frac, unsigned seed);

/* Reverses round(fraction × ntris) triangles chosen at random (fraction in [0,1]). */
HV_API hv_status hv_mesh_defect_flip(hv_mesh *m, double fraction, unsigned seed);

/* Reverses every triangle whose centroid lies on the + side (along axis 0,1,2) of
 * the mean of the triangle centroids. */
HV_API hv_status hv_mesh_defect_flip_half(hv_mesh *m, int axis);

/* Appends copies of round(fraction × ntris) distinct random triangles (fraction in
 * [0,1]); the first half of the copies (k/2 rounded down) have reversed orientation. */
HV_API hv_status hv_mesh_defect_duplicate(hv_mesh *m, double fraction, unsigned seed);

/* Unwelds: every triangle gets its own 3 vertices (nverts = 3·ntris). With
 * jitter_rel > 0 each coordinate moves by a uniform random amount of at most
 * jitter_rel × (bounding-box diagonal). */
HV_API hv_status hv_mesh_defect_soup(hv_mesh *m, double jitter_rel, unsigned seed);

#ifdef __cplusplus
}
#endif
#endif
