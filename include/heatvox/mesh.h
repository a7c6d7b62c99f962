/*
 * Triangle meshes: readers for OBJ, PLY (ascii, binary little/big endian), STL
 * (ascii, binary) and OFF; polygons are fanned into triangles and vertices are
 * welded by exact position. A defect report describes what is broken.
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
    double *verts;    /* 3 * nverts coordinates, owned */
    uint32_t *tris;   /* 3 * ntris vertex indices, owned */
} hv_mesh;

typedef struct hv_mesh_report {
    size_t vertices;            /* after welding */
    size_t triangles;           /* after fanning */
    size_t polygons_fanned;     /* input faces with more than 3 corners */
    size_t boundary_edges;      /* edges used by exactly one triangle */
    size_t nonmanifold_edges;   /* edges used by more than two triangles */
    size_t inconsistent_edges;  /* manifold edges whose two triangles traverse it the same way */
    size_t duplicate_faces;     /* triangles repeating the vertex set of an earlier one */
    size_t degenerate_faces;    /* repeated vertex index or zero area */
    size_t nonfinite_vertices;  /* NaN or Inf coordinates */
    size_t components;          /* edge-connected components of triangles */
} hv_mesh_report;

/* Reads a mesh, choosing the format by extension (.obj .ply .stl .off, any case)
 * and falling back to the content. Errors name the file and the line or byte
 * offset. An empty mesh (no triangles) is an error. The caller owns *out. */
hv_status hv_mesh_read(const char *path, hv_mesh **out);

/* Builds a mesh from arrays (copied); vertices are welded by exact position. */
hv_status hv_mesh_from_arrays(hv_mesh **out, const double *verts, size_t nverts,
                              const uint32_t *tris, size_t ntris);

void hv_mesh_destroy(hv_mesh **m);

/* Axis-aligned bounds of the finite vertices. */
hv_status hv_mesh_bounds(const hv_mesh *m, double lo[3], double hi[3]);

/* Fills the defect report. */
hv_status hv_mesh_report_compute(const hv_mesh *m, hv_mesh_report *r);

/* Writes the mesh as OBJ (temporary file then rename). */
hv_status hv_mesh_write_obj(const hv_mesh *m, const char *path);

#ifdef __cplusplus
}
#endif
#endif
