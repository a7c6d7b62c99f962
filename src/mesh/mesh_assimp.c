/* Meshes read through assimp (Debian's libassimp 5.2; the import itself in
 * mesh_assimp_guard.cpp): glTF 2.0 (.gltf, .glb), FBX, 3MF, COLLADA (.dae) and
 * DirectX (.x). OBJ, PLY, STL and OFF keep their own readers (mesh_read.c),
 * which are fuzzed and faster.
 *
 * The scene graph is flattened: each node's meshes are appended with the
 * product of the transforms from the root down to it, in double; a mesh that
 * several nodes name is appended once per node. Polygons are fanned as the
 * other readers fan them (no aiProcess_Triangulate, whose ear clipping would
 * triangulate differently from the same file saved as OBJ), and no
 * aiProcess_JoinIdenticalVertices either: it merges positions a few ULPs
 * apart, where hv__mb_finish welds exact positions only. Points and lines are
 * left out and counted. */
#include "mesh_internal.h"

#include <assimp/scene.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

/* The extensions dispatched here: every one is read by the tests into the
 * triangles of the same scene written as OBJ (tests/check_mesh_assimp.c).
 * Others assimp opens are left out: .3ds (its importer turns the scene to
 * y-up and moves meshes by their pivots), .x3d and .amf (marked experimental
 * by assimp 5.2), .blend (old Blender versions only). */
static const struct {
    const char *ext, *format;
} formats[] = {
    {".gltf", "glTF 2.0 via assimp"}, {".glb", "glTF 2.0 binary via assimp"},
    {".fbx", "FBX via assimp"},       {".3mf", "3MF via assimp"},
    {".dae", "COLLADA via assimp"},   {".x", "DirectX X via assimp"},
};

const char *hv__mesh_assimp_format(const char *path)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(slash ? slash + 1 : path, '.');
    if (!dot)
        return NULL;
    for (size_t i = 0; i < sizeof formats / sizeof formats[0]; i++)
        if (!strcasecmp(dot, formats[i].ext))
            return formats[i].format;
    return NULL;
}

/* Row-major 3x4 affine transform (the last row of aiMatrix4x4 is 0 0 0 1 in
 * every format read here; it is not looked at). */
typedef struct {
    double m[12];
} affine;

static affine affine_of(const struct aiMatrix4x4 *t)
{
    return (affine){
        {t->a1, t->a2, t->a3, t->a4, t->b1, t->b2, t->b3, t->b4, t->c1, t->c2, t->c3, t->c4}};
}

/* a * b, as transforms: b first. */
static affine affine_mul(const affine *a, const affine *b)
{
    affine r;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++) {
            double s = a->m[4 * i] * b->m[j] + a->m[4 * i + 1] * b->m[4 + j] +
                       a->m[4 * i + 2] * b->m[8 + j];
            r.m[4 * i + j] = j == 3 ? s + a->m[4 * i + 3] : s;
        }
    return r;
}

static double affine_det(const affine *a)
{
    const double *m = a->m;
    return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
           m[2] * (m[4] * m[9] - m[5] * m[8]);
}

typedef struct {
    const struct aiNode *node;
    affine world;
} walk_item;

typedef struct {
    walk_item *a;
    size_t n, cap;
} walk_stack;

static hv_status walk_push(walk_stack *s, const struct aiNode *node, const affine *world,
                           const char *path)
{
    if (s->n == s->cap) {
        size_t cap = s->cap ? 2 * s->cap : 64;
        walk_item *q = realloc(s->a, cap * sizeof *q);
        if (!q)
            return hv__error(HV_ERR_NOMEM, "%s: out of memory walking the scene's nodes", path);
        s->a = q;
        s->cap = cap;
    }
    s->a[s->n++] = (walk_item){node, *world};
    return HV_OK;
}

/* What the node tree asks for, counted before anything is allocated. */
typedef struct {
    uint64_t verts, tris, skipped;
} scene_counts;

/* Visits every node, depth first, with its transform from the root; with b
 * NULL it only counts (and checks that the meshes named exist). */
static hv_status walk_scene(const struct aiScene *sc, const char *path, mesh_builder *b,
                            scene_counts *c)
{
    walk_stack s = {0};
    const affine id = {{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}};
    hv_status st = walk_push(&s, sc->mRootNode, &id, path);
    u32vec corners = {0};
    while (!st && s.n) {
        walk_item it = s.a[--s.n];
        const struct aiNode *nd = it.node;
        const affine local = affine_of(&nd->mTransformation);
        const affine world = affine_mul(&it.world, &local);
        const int flip = affine_det(&world) < 0;
        for (unsigned k = 0; k < nd->mNumMeshes && !st; k++) {
            unsigned mi = nd->mMeshes[k];
            if (mi >= sc->mNumMeshes || !sc->mMeshes[mi]) {
                st = hv__error(HV_ERR_PARSE, "%s: assimp: node '%s' names mesh %u of %u", path,
                               nd->mName.data, mi, sc->mNumMeshes);
                break;
            }
            const struct aiMesh *me = sc->mMeshes[mi];
            if (me->mNumVertices && !me->mVertices)
                continue; /* no positions: nothing to place */
            if (!b) {
                c->verts += me->mNumVertices;
                for (unsigned f = 0; f < me->mNumFaces && me->mFaces; f++) {
                    unsigned ni = me->mFaces[f].mNumIndices;
                    if (ni >= 3)
                        c->tris += ni - 2;
                    else
                        c->skipped++;
                }
                if (c->verts > MESH_MAX_COUNT || c->tris > MESH_MAX_COUNT) {
                    st = hv__error(HV_ERR_PARSE,
                                   "%s: the scene places more than %zu %s (its meshes times the "
                                   "nodes that place them)",
                                   path, MESH_MAX_COUNT,
                                   c->verts > MESH_MAX_COUNT ? "vertices" : "triangles");
                }
                continue;
            }
            const uint32_t base = (uint32_t)b->nv;
            const double *w = world.m;
            for (unsigned v = 0; v < me->mNumVertices && !st; v++) {
                const double x = me->mVertices[v].x, y = me->mVertices[v].y, z = me->mVertices[v].z;
                st = hv__mb_add_vertex(b, x * w[0] + y * w[1] + z * w[2] + w[3],
                                       x * w[4] + y * w[5] + z * w[6] + w[7],
                                       x * w[8] + y * w[9] + z * w[10] + w[11]);
            }
            for (unsigned f = 0; f < me->mNumFaces && me->mFaces && !st; f++) {
                const struct aiFace *fc = &me->mFaces[f];
                if (fc->mNumIndices < 3)
                    continue;
                if (!fc->mIndices) {
                    st = hv__error(HV_ERR_PARSE, "%s: assimp: mesh '%s': face %u has no indices",
                                   path, me->mName.data, f);
                    break;
                }
                corners.n = 0;
                for (unsigned j = 0; j < fc->mNumIndices && !st; j++) {
                    /* a mirroring transform turns the faces inside out: undo it */
                    unsigned i = fc->mIndices[flip ? fc->mNumIndices - 1 - j : j];
                    if (i >= me->mNumVertices)
                        st = hv__error(HV_ERR_PARSE,
                                       "%s: assimp: mesh '%s': face %u uses vertex %u of %u", path,
                                       me->mName.data, f, i, me->mNumVertices);
                    else
                        st = hv__u32vec_push(&corners, base + i);
                }
                if (!st)
                    st = hv__mb_add_polygon(b, corners.a, corners.n);
            }
        }
        for (unsigned k = nd->mNumChildren; k-- > 0 && !st;)
            if (nd->mChildren && nd->mChildren[k])
                st = walk_push(&s, nd->mChildren[k], &world, path);
    }
    hv__u32vec_free(&corners);
    free(s.a);
    return st;
}

/* Metres per coordinate unit, as far as the scene tells (0: unknown). */
static double scene_unit(const struct aiScene *sc, const char *format)
{
    if (!strncmp(format, "glTF", 4))
        return 1.0; /* glTF 2.0 fixes metres */
    if (!strncmp(format, "COLLADA", 7))
        return 1.0; /* assimp scales the root by the file's <unit meter="..."> */
    if (strncmp(format, "FBX", 3))
        return 0.0;
    /* FBX: GlobalSettings' UnitScaleFactor, in centimetres */
    const struct aiMetadata *md = sc->mMetaData;
    for (unsigned i = 0; md && md->mKeys && md->mValues && i < md->mNumProperties; i++) {
        if (strcmp(md->mKeys[i].data, "UnitScaleFactor") || !md->mValues[i].mData)
            continue;
        double f = md->mValues[i].mType == AI_FLOAT    ? *(const float *)md->mValues[i].mData
                   : md->mValues[i].mType == AI_DOUBLE ? *(const double *)md->mValues[i].mData
                                                       : 0.0;
        return isfinite(f) && f > 0 ? f / 100.0 : 0.0;
    }
    return 0.0;
}

static uint32_t le32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* n bytes at offset off of the file, or of buf when not NULL; 0 when they
 * are there. */
static int read_at(const char *path, const char *buf, size_t len, uint64_t off, void *out, size_t n)
{
    if (buf) {
        if (off > len || n > len - off)
            return -1;
        memcpy(out, buf + off, n);
        return 0;
    }
    FILE *f = fopen(path, "rb");
    if (!f)
        return -1;
    int ok = fseeko(f, (off_t)off, SEEK_SET) == 0 && fread(out, 1, n, f) == n;
    fclose(f);
    return ok ? 0 : -1;
}

/* The container of a .glb (glTF 2.0, section 4.4): its 12-byte header and
 * the lengths of its JSON and BIN chunks, checked against the file before
 * assimp, which allocates whatever they declare (a 1.5 KB file declaring a
 * 1.5 GB JSON chunk took 1.6 GB in the fuzz tests). */
static hv_status check_glb(const char *path, const char *buf, size_t len, uint64_t size)
{
    unsigned char h[20];
    if (size < 20 || read_at(path, buf, len, 0, h, 20))
        return hv__error(HV_ERR_PARSE, "%s: %llu bytes: shorter than a binary glTF's headers", path,
                         (unsigned long long)size);
    if (memcmp(h, "glTF", 4))
        return hv__error(HV_ERR_PARSE, "%s: not binary glTF (no 'glTF' magic at the start)", path);
    if (le32(h + 4) != 2)
        return hv__error(HV_ERR_PARSE, "%s: binary glTF version %u; heatvox reads version 2", path,
                         le32(h + 4));
    const uint64_t total = le32(h + 8), json = le32(h + 12);
    if (total > size)
        return hv__error(HV_ERR_PARSE,
                         "%s: binary glTF of %llu bytes, says its header, in a "
                         "file of %llu",
                         path, (unsigned long long)total, (unsigned long long)size);
    if (memcmp(h + 16, "JSON", 4) || json > total - 20)
        return hv__error(HV_ERR_PARSE,
                         "%s: binary glTF: the first chunk is not JSON of at most %llu bytes", path,
                         (unsigned long long)(total - 20));
    unsigned char c[4];
    if (total >= 28 + json && !read_at(path, buf, len, 20 + json, c, 4) &&
        le32(c) > total - 28 - json)
        return hv__error(HV_ERR_PARSE,
                         "%s: binary glTF: a chunk of %u bytes after the JSON, where %llu remain",
                         path, le32(c), (unsigned long long)(total - 28 - json));
    return HV_OK;
}

hv_status hv__mesh_read_assimp(const char *path, const char *buf, size_t len, uint64_t size,
                               hv_mesh **out)
{
    *out = NULL;
    const char *format = hv__mesh_assimp_format(path);
    if (!format)
        return hv__error(HV_ERR_INTERNAL, "%s: no assimp format for this extension", path);
    const char *dot = strrchr(path, '.');
    if (!strcasecmp(dot, ".glb")) {
        hv_status st = check_glb(path, buf, len, size);
        if (st)
            return st;
    }
    char why[1024];
    void *owner = NULL;
    const struct aiScene *sc = hv__assimp_import(path, buf, len, why, sizeof why, &owner);
    if (!sc)
        return hv__error(HV_ERR_PARSE, "%s: assimp: %s", path, why);
    hv_status st = HV_OK;
    if (!sc->mRootNode) {
        hv__assimp_release(owner);
        return hv__error(HV_ERR_PARSE, "%s: assimp: the scene has no root node", path);
    }

    scene_counts c = {0};
    st = walk_scene(sc, path, NULL, &c);
    mesh_builder b;
    hv__mb_init(&b, path);
    if (!st && c.tris == 0) {
        st =
            c.skipped
                ? hv__error(HV_ERR_PARSE, "%s: no triangles (%llu points and lines: not a surface)",
                            path, (unsigned long long)c.skipped)
                : hv__error(HV_ERR_PARSE, "%s: no triangles (the scene places no mesh)", path);
    }
    /* Nodes may place one mesh many times: what they ask for is checked
     * against the memory before it is allocated (the other readers check
     * declared counts against the file's size, which says nothing here). */
    const double bytes = 24.0 * (double)c.verts + 12.0 * (double)c.tris;
    char lim[96];
    if (!st && bytes > (double)hv__memory_limit(NULL))
        st = hv__error(HV_ERR_NOMEM,
                       "%s: the scene places %llu vertices and %llu triangles (its meshes times "
                       "the nodes that place them): %.3g GB, more than %s",
                       path, (unsigned long long)c.verts, (unsigned long long)c.tris, bytes / 1e9,
                       hv__memory_limit_text(lim, sizeof lim));
    if (!st)
        st = hv__mb_reserve_verts(&b, (size_t)c.verts);
    if (!st)
        st = walk_scene(sc, path, &b, &c);
    const double unit = st ? 0.0 : scene_unit(sc, format);
    hv__assimp_release(owner);
    if (st) {
        hv__mb_free(&b);
        return st;
    }
    st = hv__mb_finish(&b, format, out);
    if (st)
        return st;
    (*out)->unit_meters = unit;
    (*out)->skipped_primitives = (size_t)c.skipped;
    return HV_OK;
}
