/* Private to the mesh module: the builder the readers fill, welding, and the
 * small text-scanning helpers the text readers share. */
#ifndef HV_MESH_INTERNAL_H
#define HV_MESH_INTERNAL_H

#include "heatvox/mesh.h"
#include "core/error.h"

#include <stdint.h>

/* Largest vertex or triangle count a mesh may hold (indices are uint32_t). */
#define MESH_MAX_COUNT ((size_t)UINT32_MAX - 1u)

/* Largest coordinate magnitude a mesh may hold: cubes of coordinate
 * differences (signed volumes, the determinants of winding numbers) must stay
 * finite in double, and so must every bounding box extent. NaN and Inf are
 * let through: the defect report counts them, bounds skip them and the
 * distance methods refuse them. */
#define MESH_MAX_COORD 1e100

/* Raw vertices and triangles as read, before welding. */
typedef struct mesh_builder {
    const char *path; /* for messages */
    size_t line;      /* input line of the next vertex, for messages; 0: not a text line */
    double *v;
    size_t nv, vcap;
    uint32_t *t;
    size_t nt, tcap;
    size_t polygons_fanned;
    size_t nonfinite_vertex, nonfinite_line; /* the first NaN/Inf vertex, 1-based; 0: none */
} mesh_builder;

void hv__mb_init(mesh_builder *b, const char *path);
void hv__mb_free(mesh_builder *b);
/* Makes room for n more vertices (n already checked against the file size). */
hv_status hv__mb_reserve_verts(mesh_builder *b, size_t n);
/* Refuses finite coordinates beyond MESH_MAX_COORD, naming the vertex (and
 * b->line when set). */
hv_status hv__mb_add_vertex(mesh_builder *b, double x, double y, double z);
hv_status hv__mb_add_tri(mesh_builder *b, uint32_t a, uint32_t c1, uint32_t c2);
/* Fans a polygon of k >= 3 corners (v0, vi, vi+1); counts it when k > 3. */
hv_status hv__mb_add_polygon(mesh_builder *b, const uint32_t *idx, size_t k);
/* Checks indices, requires a triangle, welds and hands the result to *out. The
 * builder is emptied either way. */
hv_status hv__mb_finish(mesh_builder *b, const char *format, hv_mesh **out);

/* Welds verts by exact position, drops vertices tris do not use, and rewrites
 * tris in place (indices must be < nverts). On success *wverts (owned) holds *wn
 * vertices, in order of first appearance; *nreferenced (may be NULL) counts the
 * input vertices some triangle used. */
hv_status hv__mesh_weld(const double *verts, size_t nverts, uint32_t *tris, size_t ntris,
                        double **wverts, size_t *wn, size_t *nreferenced);

/* Builds a mesh from arrays exactly as given (copied): no welding, no vertex
 * dropped, so a producer that guarantees its own topology keeps it even where
 * two vertices share a position (hv_mesh_from_arrays would merge them). For
 * the isosurface extraction (src/mesh/vdb_mesh.cpp); indices must be < nverts. */
hv_status hv__mesh_from_arrays_as_is(hv_mesh **out, const double *verts, size_t nverts,
                                     const uint32_t *tris, size_t ntris);

/* The whole of path in a new buffer (*out, freed by the caller) with a NUL
 * byte after its *len bytes: regular files, and pipes up to a bound;
 * directories, devices and sockets are refused (mesh_read.c). */
hv_status hv__mesh_read_file(const char *path, char **out, size_t *len);

/* Point clouds (points.c, ply.c). A reader adds each point through
 * hv__points_add, which checks it (finite, a normal of non-zero length) and
 * names the place `where` ("line 12", "point 7") in its message. A cloud
 * has normals on every point or on none: the first point decides. */
typedef struct points_builder {
    const char *path;
    double *xyz, *nrm;
    size_t n, cap;
    int negative; /* some normal component was negative */
    int nonunit;  /* some normal was not of unit length */
    int values;   /* 6: x y z nx ny nz per point, 3: x y z (unoriented), 0: no point yet */
} points_builder;
hv_status hv__points_reserve(points_builder *b, size_t n);
/* Adds x y z (values 3) or x y z nx ny nz (values 6) from p. */
hv_status hv__points_add(points_builder *b, const double *p, int values, const char *where);
/* PLY: whether the header has a vertex element and no faces (ply.c), and
 * the vertex element's x y z (nx ny nz where it has them) into b. */
int hv__ply_is_points(const char *buf, size_t len);
hv_status hv__points_read_ply(const char *path, const char *buf, size_t len, points_builder *b);

/* A growable array of uint32_t for polygon corners (no fixed limit). */
typedef struct u32vec {
    uint32_t *a;
    size_t n, cap;
} u32vec;
hv_status hv__u32vec_push(u32vec *v, uint32_t x);
void hv__u32vec_free(u32vec *v);

/* Text scanning. Buffers handed to readers end with a NUL byte (not counted in
 * their length), so scanning functions may look one byte past a token. */
static inline int mesh_is_hspace(char c) { return c == ' ' || c == '\t' || c == '\v' || c == '\f'; }
static inline int mesh_is_space(char c) { return mesh_is_hspace(c) || c == '\r' || c == '\n'; }
static inline int mesh_is_delim(char c) { return mesh_is_space(c) || c == '\0'; }

/* Parses a number at s (no leading space skipped) in the C locale, whatever the
 * process locale; accepts what strtod accepts (also nan, inf). *end is the first
 * byte after it. Returns 0 on success, -1 if s does not start a number. */
int hv__mesh_parse_double(const char *s, const char **end, double *out);
/* Parses an optionally signed decimal integer; -1 on no digits or overflow. */
int hv__mesh_parse_i64(const char *s, const char **end, int64_t *out);

/* Shows up to 24 bytes of a token for an error message (static buffer per thread). */
const char *hv__mesh_token_preview(const char *s, const char *end);

/* Format readers: buf has len bytes followed by a NUL. */
hv_status hv__mesh_read_obj(const char *path, const char *buf, size_t len, hv_mesh **out);
hv_status hv__mesh_read_ply(const char *path, const char *buf, size_t len, hv_mesh **out);
hv_status hv__mesh_read_stl(const char *path, const char *buf, size_t len, hv_mesh **out);
hv_status hv__mesh_read_off(const char *path, const char *buf, size_t len, hv_mesh **out);

/* Formats read through assimp (mesh_assimp.c). hv__mesh_assimp_format names
 * the one the extension of path selects (NULL: none). hv__mesh_read_assimp
 * reads the file at path, of size bytes, or with buf not NULL the len (=
 * size) bytes of buf (a pipe's content: files the scene refers to, such as a
 * .gltf's buffers, are not found then). */
const char *hv__mesh_assimp_format(const char *path);
hv_status hv__mesh_read_assimp(const char *path, const char *buf, size_t len, uint64_t size,
                               hv_mesh **out);
/* assimp's import of path (or of buf's len bytes), by the one reader of
 * assimp that path's extension names, with assimp's failed checks turned into
 * a failed import (mesh_assimp_guard.cpp). On failure NULL, with the reason in
 * err; else the scene, which *owner holds until hv__assimp_release(*owner). */
struct aiScene;
const struct aiScene *hv__assimp_import(const char *path, const char *buf, size_t len, char *err,
                                        size_t errsize, void **owner);
void hv__assimp_release(void *owner);

/* Splitmix64, for the defect makers. */
static inline uint64_t mesh_rng_next(uint64_t *s)
{
    uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}
static inline double mesh_rng_uniform(uint64_t *s) /* [0,1) */
{
    return (double)(mesh_rng_next(s) >> 11) * (1.0 / 9007199254740992.0);
}

#endif
