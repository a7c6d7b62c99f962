// The OpenVDB reader behind include/heatvox/vdb.h: lists the grids of a file,
// reads float, vec3 and mask grids onto dense heatvox grids, index boxes and
// metadata. Files are checked against their size (vdb_check.h) before OpenVDB
// reads them.
#include "heatvox/vdb.h"
#include "vdb_internal.h"
#include "vdb_check.h"

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

using namespace hv_vdb_shim;

namespace
{

using openvdb::Coord;
using openvdb::CoordBBox;
using openvdb::Vec3d;

std::string fmt_vec(const Vec3d &v)
{
    char buf[128];
    snprintf(buf, sizeof buf, "(%.9g, %.9g, %.9g)", v[0], v[1], v[2]);
    return buf;
}

// ---- file access --------------------------------------------------------------

void check_readable(const char *path)
{
    if (!path || !*path)
        fail(HV_ERR_INVALID_ARG, "input .vdb path is empty");
    FILE *f = fopen(path, "rb");
    if (!f)
        fail(HV_ERR_IO, std::string(path) + ": cannot open: " + strerror(errno));
    fclose(f);
}

// Opens without delayed loading: the file is read completely by readGrid, so
// nothing stays mapped and truncated data is found now rather than later.
// OpenVDB trusts the lengths and counts it reads, so the file's layout is
// checked against its size first (vdb_check.h): the header, metadata,
// descriptors and transforms on open, each tree before readGrid reads it.
struct OpenFile {
    openvdb::io::File file;
    std::string path;
    std::unique_ptr<hv_vdb_check::FileCheck> layout;
    explicit OpenFile(const char *p) : file(p), path(p)
    {
        init_vdb();
        check_readable(p);
        try {
            layout.reset(new hv_vdb_check::FileCheck(path));
        } catch (const hv_vdb_check::Rejected &e) {
            fail(e.st, e.msg);
        }
        try {
            file.open(false);
        } catch (const openvdb::Exception &e) {
            fail(HV_ERR_IO, path + ": not a readable OpenVDB file (" + e.what() + ")");
        }
    }
    ~OpenFile()
    {
        try {
            if (file.isOpen())
                file.close();
        } catch (...) {
        }
    }

    std::string names() const
    {
        std::string s;
        for (auto it = file.beginName(); it != file.endName(); ++it)
            s += (s.empty() ? "'" : ", '") + it.gridName() + "'";
        return s.empty() ? "no grids" : s;
    }

    void require(const char *name)
    {
        if (!name || !*name)
            fail(HV_ERR_INVALID_ARG, path + ": grid name is empty");
        if (!file.hasGrid(name))
            fail(HV_ERR_INVALID_ARG,
                 path + ": no grid named '" + name + "' (the file has " + names() + ")");
    }

    openvdb::GridBase::Ptr read(const char *name)
    {
        require(name);
        try {
            layout->check_tree(name);
        } catch (const hv_vdb_check::Rejected &e) {
            fail(e.st, e.msg);
        }
        try {
            return file.readGrid(name);
        } catch (const openvdb::Exception &e) {
            fail(HV_ERR_IO, path + ": grid '" + name + "' cannot be read (" + e.what() + ")");
        }
    }
};

// The transform must be linear, axis-aligned and uniform with positive scale;
// returns h and the world position of index (0,0,0).
bool uniform_transform(const openvdb::math::Transform &xf, double *h, Vec3d *t0)
{
    if (!xf.isLinear())
        return false;
    const openvdb::math::Mat4d m = xf.baseMap()->getAffineMap()->getMat4();
    const double s = m[0][0];
    if (!(s > 0))
        return false;
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            const double want = r == c ? s : 0.0;
            if (std::fabs(m[r][c] - want) > 1e-9 * s)
                return false;
        }
    *h = s;
    *t0 = xf.indexToWorld(Vec3d(0, 0, 0));
    return true;
}

void require_uniform(const openvdb::GridBase &g, const std::string &path, double *h, Vec3d *t0)
{
    if (!uniform_transform(g.transform(), h, t0)) {
        const Vec3d vs = g.transform().voxelSize();
        fail(HV_ERR_UNSUPPORTED,
             path + ": grid '" + g.getName() +
                 "' does not have a uniform axis-aligned linear transform (voxel size " +
                 fmt_vec(vs) + ", map " + g.transform().mapType() +
                 "); heatvox grids need cubic voxels");
    }
}

bool meta_box(const openvdb::GridBase &g, const char *kmin, const char *kmax, CoordBBox *box)
{
    auto lo = g.getMetadata<openvdb::Vec3IMetadata>(kmin);
    auto hi = g.getMetadata<openvdb::Vec3IMetadata>(kmax);
    if (!lo || !hi)
        return false;
    *box = CoordBBox(Coord(lo->value()), Coord(hi->value()));
    return true;
}

// The default read box of a grid whose tree may not be loaded (metadata only):
// heatvox's block, else the active bounding box from the stats metadata, else
// (tree loaded) the evaluated active bounding box.
CoordBBox default_box(const openvdb::GridBase &g, const std::string &path, bool tree_loaded)
{
    CoordBBox box;
    if (meta_box(g, BLOCK_MIN, BLOCK_MAX, &box))
        return box;
    if (!tree_loaded && meta_box(g, openvdb::GridBase::META_FILE_BBOX_MIN,
                                 openvdb::GridBase::META_FILE_BBOX_MAX, &box))
        return box;
    if (tree_loaded) {
        box = g.evalActiveVoxelBoundingBox();
        if (!box.empty())
            return box;
    }
    fail(HV_ERR_INVALID_ARG,
         path + ": grid '" + g.getName() + "' has no active voxels; pass an index box to read it");
}

CoordBBox read_box(const openvdb::GridBase &g, const std::string &path, const hv_vdb_read_opts *o)
{
    if (!o || !o->use_box)
        return default_box(g, path, true);
    for (int a = 0; a < 3; a++)
        if (o->box_hi[a] < o->box_lo[a]) {
            char buf[160];
            snprintf(buf, sizeof buf, ": index box is empty along %c (lo %d > hi %d)", "xyz"[a],
                     o -> box_lo[a], o -> box_hi[a]);
            fail(HV_ERR_INVALID_ARG, path + buf);
        }
    return CoordBBox(Coord(o->box_lo[0], o->box_lo[1], o->box_lo[2]),
                     Coord(o->box_hi[0], o->box_hi[1], o->box_hi[2]));
}

// The block of index box `box` under g's transform: its size, voxel size and
// lower corner (the corner of voxel box.min(), half a voxel below its centre).
struct Block {
    int n[3];
    double h;
    double origin[3];
};

Block block_of(const openvdb::GridBase &g, const std::string &path, const CoordBBox &box)
{
    Block b;
    Vec3d t0;
    require_uniform(g, path, &b.h, &t0);
    for (int a = 0; a < 3; a++) {
        const int64_t len = (int64_t)box.max()[a] - (int64_t)box.min()[a] + 1;
        if (len <= 0 || len > std::numeric_limits<int>::max())
            fail(HV_ERR_INVALID_ARG, path + ": grid '" + g.getName() + "': index box too large");
        b.n[a] = (int)len;
        b.origin[a] = t0[a] + ((double)box.min()[a] - 0.5) * b.h;
    }
    return b;
}

// A new dense grid for box with the geometry of g's transform.
hv_grid *new_dense(const openvdb::GridBase &g, const std::string &path, const CoordBBox &box)
{
    const Block b = block_of(g, path, box);
    hv_grid *out = nullptr;
    hv_status st = hv_grid_create(&out, 3, b.n, b.h, b.origin);
    if (st)
        fail(st, path + ": grid '" + g.getName() + "': " + hv_last_error());
    return out;
}

// Calls put(linear index, value) for every voxel of box, parallel over z.
template <class GridT, class F> void for_box(const GridT &grid, const CoordBBox &box, F &&put)
{
    const Coord lo = box.min();
    const int64_t nx = box.dim()[0], ny = box.dim()[1];
    tbb::parallel_for(tbb::blocked_range<int>(box.min()[2], box.max()[2] + 1),
                      [&](const tbb::blocked_range<int> &r) {
                          auto acc = grid.getConstAccessor();
                          for (int k = r.begin(); k != r.end(); k++)
                              for (int j = lo[1]; j <= box.max()[1]; j++)
                                  for (int i = lo[0]; i <= box.max()[0]; i++) {
                                      const Coord c(i, j, k);
                                      const size_t idx =
                                          (size_t)(i - lo[0]) +
                                          (size_t)nx * ((size_t)(j - lo[1]) +
                                                        (size_t)ny * (size_t)(k - lo[2]));
                                      put(idx, acc, c);
                                  }
                      });
}

struct GridOwner {
    hv_grid *g = nullptr;
    ~GridOwner() { hv_grid_destroy(&g); }
    hv_grid *release()
    {
        hv_grid *r = g;
        g = nullptr;
        return r;
    }
};

// ---- tiles ------------------------------------------------------------------

constexpr size_t TILE_CELLS = HV_TILE * HV_TILE * HV_TILE;

struct TilesOwner {
    hv_tiles *t = nullptr;
    ~TilesOwner() { hv_tiles_destroy(&t); }
    hv_tiles *release()
    {
        hv_tiles *r = t;
        t = nullptr;
        return r;
    }
};

hv_tiles *new_tiles_like(const hv_tiles *like, const std::string &path, const char *name)
{
    hv_tiles *t = nullptr;
    hv_status st = hv_tiles_create_like(&t, like, 0.0f);
    if (st)
        fail(st, path + ": grid '" + name + "': " + hv_last_error());
    return t;
}

// The corners (block indices i, j, k) of the 8^3 tiles of block `box` that hold
// an active voxel of tree inside the block, sorted by (k, j, i). Found from the
// tree alone: the active voxels of its leaves, and its active tiles (every
// voxel of which is active). Tiles start at box.min() + multiples of 8 and
// leaves at multiples of 8, so a leaf touches up to 2 tiles along each axis.
template <class TreeT> std::vector<int32_t> active_tiles(const TreeT &tree, const CoordBBox &box)
{
    using LeafT = typename TreeT::LeafNodeType;
    using Key = std::array<int32_t, 3>; // tile index along k, j, i: sorts as wanted
    const Coord lo = box.min();
    auto key = [&lo](const Coord &c) {
        return Key{(c[2] - lo[2]) / HV_TILE, (c[1] - lo[1]) / HV_TILE, (c[0] - lo[0]) / HV_TILE};
    };
    std::vector<const LeafT *> leaves;
    for (auto it = tree.cbeginLeaf(); it; ++it)
        if (it->getNodeBoundingBox().hasOverlap(box))
            leaves.push_back(it.getLeaf());
    tbb::enumerable_thread_specific<std::vector<Key>> found;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves.size()), [&](const tbb::blocked_range<
                                                                        size_t> &r) {
        auto &mine = found.local();
        for (size_t l = r.begin(); l != r.end(); l++) {
            const LeafT &leaf = *leaves[l];
            const Key k0 = key(Coord::maxComponent(leaf.origin(), lo));
            unsigned seen = 0; // bit 4dk + 2dj + di of tile k0 + (dk, dj, di)
            for (auto v = leaf.getValueMask().beginOn(); v; ++v) {
                const Coord c = leaf.offsetToGlobalCoord(v.pos());
                if (!box.isInside(c))
                    continue;
                const Key k = key(c);
                seen |= 1u << (4 * (k[0] - k0[0]) + 2 * (k[1] - k0[1]) + (k[2] - k0[2]));
            }
            for (int b = 0; b < 8; b++)
                if (seen >> b & 1)
                    mine.push_back(Key{k0[0] + (b >> 2), k0[1] + (b >> 1 & 1), k0[2] + (b & 1)});
        }
    });
    std::vector<Key> keys;
    for (auto &v : found)
        keys.insert(keys.end(), v.begin(), v.end());
    typename TreeT::ValueOnCIter it = tree.cbeginValueOn();
    it.setMaxDepth(TreeT::ValueOnCIter::LEAF_DEPTH - 1);
    for (; it; ++it) {
        CoordBBox b = it.getBoundingBox();
        b.intersect(box);
        if (b.empty())
            continue;
        const Key a = key(b.min()), z = key(b.max());
        for (int32_t k = a[0]; k <= z[0]; k++)
            for (int32_t j = a[1]; j <= z[1]; j++)
                for (int32_t i = a[2]; i <= z[2]; i++)
                    keys.push_back(Key{k, j, i});
    }
    tbb::parallel_sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    std::vector<int32_t> ijk(3 * keys.size());
    for (size_t q = 0; q < keys.size(); q++)
        for (int a = 0; a < 3; a++)
            ijk[3 * q + a] = HV_TILE * keys[q][2 - a];
    return ijk;
}

// Fills tiles t of block `box` from tree: put(index into t->v, value) for
// every cell, the tree's active voxels inside the block into t->on and
// t->active. Each tile is copied from the up to 8 leaves it overlaps, or from
// the tile value of the tree where there is no leaf.
template <class TreeT, class Put>
void fill_tiles(const TreeT &tree, const CoordBBox &box, hv_tiles *t, Put &&put)
{
    using LeafT = typename TreeT::LeafNodeType;
    using ValueT = typename TreeT::ValueType;
    const int D = (int)LeafT::DIM;
    static_assert(LeafT::DIM == HV_TILE, "a tile and a leaf span the same cells");
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, t->count), [&](const tbb::blocked_range<size_t> &r) {
            openvdb::tree::ValueAccessor<const TreeT> acc(tree);
            for (size_t q = r.begin(); q != r.end(); q++) {
                const int32_t *c = t->ijk + 3 * q;
                const Coord T = box.min().offsetBy(c[0], c[1], c[2]);
                uint64_t on[HV_TILE] = {0};
                // T & ~(D-1) rounds down to the leaf lattice, negatives included.
                for (int lz = T[2] & ~(D - 1); lz < T[2] + HV_TILE; lz += D)
                    for (int ly = T[1] & ~(D - 1); ly < T[1] + HV_TILE; ly += D)
                        for (int lx = T[0] & ~(D - 1); lx < T[0] + HV_TILE; lx += D) {
                            const Coord L(lx, ly, lz);
                            int b0[3], b1[3]; // the overlap, in tile cells
                            for (int a = 0; a < 3; a++) {
                                b0[a] = std::max(L[a], T[a]) - T[a];
                                b1[a] = std::min(L[a] + D, T[a] + HV_TILE) - T[a];
                            }
                            const LeafT *leaf = acc.probeConstLeaf(L);
                            if (leaf) {
                                const ValueT *src = leaf->buffer().data();
                                const auto &mask = leaf->getValueMask();
                                for (int k = b0[2]; k < b1[2]; k++)
                                    for (int j = b0[1]; j < b1[1]; j++) {
                                        const size_t row =
                                            q * TILE_CELLS + (size_t)HV_TILE * (j + HV_TILE * k);
                                        for (int i = b0[0]; i < b1[0]; i++) {
                                            const openvdb::Index off =
                                                LeafT::coordToOffset(T.offsetBy(i, j, k));
                                            put(row + (size_t)i, src[off]);
                                            on[k] |= (uint64_t)mask.isOn(off) << (i + HV_TILE * j);
                                        }
                                    }
                            } else {
                                const ValueT fill = acc.getValue(L);
                                const uint64_t fill_on = acc.isValueOn(L) ? 1 : 0;
                                for (int k = b0[2]; k < b1[2]; k++)
                                    for (int j = b0[1]; j < b1[1]; j++) {
                                        const size_t row =
                                            q * TILE_CELLS + (size_t)HV_TILE * (j + HV_TILE * k);
                                        for (int i = b0[0]; i < b1[0]; i++) {
                                            put(row + (size_t)i, fill);
                                            on[k] |= fill_on << (i + HV_TILE * j);
                                        }
                                    }
                            }
                        }
                // Cells beyond the block are never active.
                const int ni = std::min(HV_TILE, t->n[0] - c[0]),
                          nj = std::min(HV_TILE, t->n[1] - c[1]),
                          nk = std::min(HV_TILE, t->n[2] - c[2]);
                const uint64_t row = ((uint64_t)1 << ni) - 1;
                uint64_t keep = 0;
                for (int j = 0; j < nj; j++)
                    keep |= row << (HV_TILE * j);
                for (int k = 0; k < HV_TILE; k++)
                    on[k] &= k < nk ? keep : 0;
                memcpy(t->on + HV_TILE * q, on, sizeof on);
            }
        });
    size_t active = 0;
    for (size_t w = 0; w < HV_TILE * t->count; w++)
        active += (size_t)__builtin_popcountll(t->on[w]);
    t->active = active;
}

// The index box of like's block in g's index space. like must lie on g's
// lattice (as tiles read from the same file do): the same voxel size, and
// its corner half a voxel below an index (within 1e-6 voxels).
CoordBBox like_box(const openvdb::GridBase &g, const std::string &path, const hv_tiles *like)
{
    double h;
    Vec3d t0;
    require_uniform(g, path, &h, &t0);
    bool ok = std::fabs(like->h - h) <= 1e-6 * h;
    double s[3], r[3];
    for (int a = 0; a < 3; a++) {
        s[a] = (like->origin[a] - t0[a]) / h + 0.5;
        r[a] = std::nearbyint(s[a]);
        ok = ok && std::fabs(s[a] - r[a]) <= 1e-6 && std::fabs(r[a]) < 1e9 && like->n[a] > 0 &&
             r[a] + like->n[a] - 1 <= std::numeric_limits<int>::max();
    }
    if (!ok) {
        char buf[320];
        snprintf(buf, sizeof buf,
                 "' has a different transform from the tiles' block (voxel size %.9g vs %.9g; "
                 "block corner %.3g, %.3g, %.3g voxels off the grid's lattice)",
                 h, like->h, s[0] - r[0], s[1] - r[1], s[2] - r[2]);
        fail(HV_ERR_INVALID_ARG, path + ": grid '" + g.getName() + buf);
    }
    const Coord lo((int)r[0], (int)r[1], (int)r[2]);
    for (size_t q = 0; q < like->count; q++)
        for (int a = 0; a < 3; a++) {
            const int32_t c = like->ijk[3 * q + a];
            if (c % HV_TILE || c < 0 || c >= like->n[a])
                fail(HV_ERR_INVALID_ARG, path + ": grid '" + g.getName() +
                                             "': a tile of like is not on its block's 8^3 lattice");
        }
    return CoordBBox(lo, lo.offsetBy(like->n[0] - 1, like->n[1] - 1, like->n[2] - 1));
}

} // namespace

extern "C" {

hv_status hv_vdb_list(const char *path, hv_vdb_grid_info *info, size_t cap, size_t *count)
{
    return guarded(path ? path : "hv_vdb_list", [&] {
        if (!count || (cap && !info))
            fail(HV_ERR_INVALID_ARG, "hv_vdb_list: count is NULL or info is NULL with cap > 0");
        *count = 0;
        OpenFile f(path);
        auto grids = f.file.readAllGridMetadata();
        size_t i = 0;
        for (auto &g : *grids) {
            if (i < cap) {
                hv_vdb_grid_info &d = info[i];
                memset(&d, 0, sizeof d);
                snprintf(d.name, sizeof d.name, "%s", g->getName().c_str());
                snprintf(d.value_type, sizeof d.value_type, "%s", g->valueType().c_str());
                d.grid_class = (int)g->getGridClass();
                double h;
                Vec3d t0;
                d.uniform = uniform_transform(g->transform(), &h, &t0) ? 1 : 0;
                const Vec3d vs = g->transform().voxelSize();
                const Vec3d w0 = g->transform().indexToWorld(Vec3d(0, 0, 0));
                for (int a = 0; a < 3; a++) {
                    d.voxel_size[a] = vs[a];
                    d.index0_world[a] = w0[a];
                }
                CoordBBox box;
                auto cnt = g->getMetadata<openvdb::Int64Metadata>(
                    openvdb::GridBase::META_FILE_VOXEL_COUNT);
                if (!meta_box(*g, openvdb::GridBase::META_FILE_BBOX_MIN,
                              openvdb::GridBase::META_FILE_BBOX_MAX, &box) ||
                    !cnt) {
                    auto full = f.read(g->getName().c_str());
                    box = full->evalActiveVoxelBoundingBox();
                    d.active_voxels = (int64_t)full->activeVoxelCount();
                } else {
                    d.active_voxels = cnt->value();
                }
                if (d.active_voxels == 0 || box.empty())
                    box = CoordBBox(Coord(0), Coord(-1));
                for (int a = 0; a < 3; a++) {
                    d.bbox_lo[a] = box.min()[a];
                    d.bbox_hi[a] = box.max()[a];
                }
            }
            i++;
        }
        *count = i;
        return HV_OK;
    });
}

hv_status hv_vdb_read_float(const char *path, const char *name, const hv_vdb_read_opts *opts,
                            hv_grid **out, int *grid_class)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_vdb_read_float: out is NULL");
    *out = nullptr;
    return guarded(path ? path : "hv_vdb_read_float", [&] {
        OpenFile f(path);
        auto base = f.read(name);
        const CoordBBox box = read_box(*base, f.path, opts);
        GridOwner o;
        o.g = new_dense(*base, f.path, box);
        hv_grid *g = o.g;
        auto put = [g](size_t idx, auto &acc, const Coord &c) {
            g->v[idx] = (float)acc.getValue(c);
        };
        if (auto fg = openvdb::GridBase::grid<openvdb::FloatGrid>(base))
            for_box(*fg, box, put);
        else if (auto dg = openvdb::GridBase::grid<openvdb::DoubleGrid>(base))
            for_box(*dg, box, put);
        else
            fail(HV_ERR_INVALID_ARG, f.path + ": grid '" + name + "' holds " + base->valueType() +
                                         " values, not float or double");
        if (grid_class)
            *grid_class = (int)base->getGridClass();
        *out = o.release();
        return HV_OK;
    });
}

hv_status hv_vdb_read_float_tiles(const char *path, const char *name, const int lo[3],
                                  const int hi[3], hv_tiles **out, int *grid_class)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_vdb_read_float_tiles: out is NULL");
    *out = nullptr;
    return guarded(path ? path : "hv_vdb_read_float_tiles", [&] {
        if (!lo || !hi)
            fail(HV_ERR_INVALID_ARG, "hv_vdb_read_float_tiles: lo and hi are required");
        OpenFile f(path);
        auto base = f.read(name);
        hv_vdb_read_opts opts = {};
        opts.use_box = 1;
        for (int a = 0; a < 3; a++) {
            opts.box_lo[a] = lo[a];
            opts.box_hi[a] = hi[a];
        }
        const CoordBBox box = read_box(*base, f.path, &opts);
        const Block b = block_of(*base, f.path, box);
        TilesOwner o;
        auto read = [&](const auto &tree) {
            std::vector<int32_t> ijk = active_tiles(tree, box);
            hv_tiles like = {};
            for (int a = 0; a < 3; a++) {
                like.n[a] = b.n[a];
                like.origin[a] = b.origin[a];
            }
            like.h = b.h;
            like.count = ijk.size() / 3;
            like.ijk = ijk.data();
            o.t = new_tiles_like(&like, f.path, name);
            float *v = o.t->v;
            fill_tiles(tree, box, o.t, [v](size_t c, const auto &val) { v[c] = (float)val; });
        };
        if (auto fg = openvdb::GridBase::grid<openvdb::FloatGrid>(base))
            read(fg->tree());
        else if (auto dg = openvdb::GridBase::grid<openvdb::DoubleGrid>(base))
            read(dg->tree());
        else
            fail(HV_ERR_INVALID_ARG, f.path + ": grid '" + name + "' holds " + base->valueType() +
                                         " values, not float or double");
        if (grid_class)
            *grid_class = (int)base->getGridClass();
        *out = o.release();
        return HV_OK;
    });
}

hv_status hv_vdb_read_tiles_like(const char *path, const char *name, const hv_tiles *like,
                                 hv_tiles *out[3], int *ncomp)
{
    if (!out || !ncomp)
        return hv__error(HV_ERR_INVALID_ARG, "hv_vdb_read_tiles_like: out or ncomp is NULL");
    out[0] = out[1] = out[2] = nullptr;
    *ncomp = 0;
    return guarded(path ? path : "hv_vdb_read_tiles_like", [&] {
        if (!like || (like->count && !like->ijk))
            fail(HV_ERR_INVALID_ARG, "hv_vdb_read_tiles_like: like is NULL or has no tiles");
        OpenFile f(path);
        auto base = f.read(name);
        const CoordBBox box = like_box(*base, f.path, like);
        TilesOwner o[3];
        auto scalar = [&](const auto &tree) {
            o[0].t = new_tiles_like(like, f.path, name);
            float *v = o[0].t->v;
            fill_tiles(tree, box, o[0].t, [v](size_t c, const auto &val) { v[c] = (float)val; });
            *ncomp = 1;
        };
        auto vector = [&](const auto &tree) {
            for (auto &c : o)
                c.t = new_tiles_like(like, f.path, name);
            float *x = o[0].t->v, *y = o[1].t->v, *z = o[2].t->v;
            fill_tiles(tree, box, o[0].t, [x, y, z](size_t c, const auto &val) {
                x[c] = (float)val[0];
                y[c] = (float)val[1];
                z[c] = (float)val[2];
            });
            for (int c = 1; c < 3; c++) {
                if (like->count)
                    memcpy(o[c].t->on, o[0].t->on, HV_TILE * like->count * sizeof(uint64_t));
                o[c].t->active = o[0].t->active;
            }
            *ncomp = 3;
        };
        if (auto fg = openvdb::GridBase::grid<openvdb::FloatGrid>(base))
            scalar(fg->tree());
        else if (auto dg = openvdb::GridBase::grid<openvdb::DoubleGrid>(base))
            scalar(dg->tree());
        else if (auto sg = openvdb::GridBase::grid<openvdb::Vec3SGrid>(base))
            vector(sg->tree());
        else if (auto vg = openvdb::GridBase::grid<openvdb::Vec3DGrid>(base))
            vector(vg->tree());
        else
            fail(HV_ERR_INVALID_ARG, f.path + ": grid '" + name + "' holds " + base->valueType() +
                                         " values, not float, double, vec3s or vec3d");
        for (int c = 0; c < *ncomp; c++)
            out[c] = o[c].release();
        return HV_OK;
    });
}

hv_status hv_vdb_read_vec3(const char *path, const char *name, const hv_vdb_read_opts *opts,
                           hv_grid **gx, hv_grid **gy, hv_grid **gz)
{
    if (!gx || !gy || !gz)
        return hv__error(HV_ERR_INVALID_ARG, "hv_vdb_read_vec3: an output pointer is NULL");
    *gx = *gy = *gz = nullptr;
    return guarded(path ? path : "hv_vdb_read_vec3", [&] {
        OpenFile f(path);
        auto base = f.read(name);
        const CoordBBox box = read_box(*base, f.path, opts);
        GridOwner ox, oy, oz;
        ox.g = new_dense(*base, f.path, box);
        oy.g = new_dense(*base, f.path, box);
        oz.g = new_dense(*base, f.path, box);
        hv_grid *x = ox.g, *y = oy.g, *z = oz.g;
        auto put = [x, y, z](size_t idx, auto &acc, const Coord &c) {
            const auto v = acc.getValue(c);
            x->v[idx] = (float)v[0];
            y->v[idx] = (float)v[1];
            z->v[idx] = (float)v[2];
        };
        if (auto sg = openvdb::GridBase::grid<openvdb::Vec3SGrid>(base))
            for_box(*sg, box, put);
        else if (auto dg = openvdb::GridBase::grid<openvdb::Vec3DGrid>(base))
            for_box(*dg, box, put);
        else
            fail(HV_ERR_INVALID_ARG, f.path + ": grid '" + name + "' holds " + base->valueType() +
                                         " values, not vec3s or vec3d");
        *gx = ox.release();
        *gy = oy.release();
        *gz = oz.release();
        return HV_OK;
    });
}

hv_status hv_vdb_read_mask(const char *path, const char *name, const hv_vdb_read_opts *opts,
                           hv_grid **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_vdb_read_mask: out is NULL");
    *out = nullptr;
    return guarded(path ? path : "hv_vdb_read_mask", [&] {
        OpenFile f(path);
        auto base = f.read(name);
        const CoordBBox box = read_box(*base, f.path, opts);
        GridOwner o;
        o.g = new_dense(*base, f.path, box);
        hv_status st = hv_grid_add_mask(o.g);
        if (st)
            return st;
        hv_grid *g = o.g;
        auto set = [g](size_t idx, bool s) {
            g->v[idx] = s ? 1.0f : 0.0f;
            g->solid[idx] = s ? 1 : 0;
        };
        const bool ls = base->getGridClass() == openvdb::GRID_LEVEL_SET;
        auto by_value = [&](size_t idx, auto &acc, const Coord &c) {
            const double v = (double)acc.getValue(c);
            set(idx, ls ? v < 0 : v != 0);
        };
        auto by_state = [&](size_t idx, auto &acc, const Coord &c) {
            set(idx, acc.isValueOn(c) || (bool)acc.getValue(c));
        };
        if (auto bg = openvdb::GridBase::grid<openvdb::BoolGrid>(base))
            for_box(*bg, box, by_state);
        else if (auto mg = openvdb::GridBase::grid<openvdb::MaskGrid>(base))
            for_box(*mg, box, by_state);
        else if (auto fg = openvdb::GridBase::grid<openvdb::FloatGrid>(base))
            for_box(*fg, box, by_value);
        else if (auto dg = openvdb::GridBase::grid<openvdb::DoubleGrid>(base))
            for_box(*dg, box, by_value);
        else
            fail(HV_ERR_INVALID_ARG, f.path + ": grid '" + name + "' holds " + base->valueType() +
                                         " values; a mask must be bool, mask, float or double");
        *out = o.release();
        return HV_OK;
    });
}

hv_status hv_vdb_common_box(const char *path, const char *const *names, size_t count, int lo[3],
                            int hi[3])
{
    return guarded(path ? path : "hv_vdb_common_box", [&] {
        if (!names || count == 0 || !lo || !hi)
            fail(HV_ERR_INVALID_ARG, "hv_vdb_common_box: names, lo and hi are required");
        OpenFile f(path);
        CoordBBox all;
        double h0 = 0;
        Vec3d t0;
        std::string first;
        for (size_t i = 0; i < count; i++) {
            f.require(names[i]);
            auto g = f.file.readGridMetadata(names[i]);
            double h;
            Vec3d t;
            require_uniform(*g, f.path, &h, &t);
            if (i == 0) {
                h0 = h;
                t0 = t;
                first = names[i];
            } else {
                // Same voxel size, and index lattices that coincide: the
                // index-0 centres may differ only by a whole number of voxels.
                // Such grids still cannot share a box unless the offset is 0,
                // since heatvox reads by index; say exactly what differs.
                const bool same_h = std::fabs(h - h0) <= 1e-9 * h0;
                const bool same_t = (t - t0).length() <= 1e-6 * h0;
                if (!same_h || !same_t)
                    fail(HV_ERR_INVALID_ARG,
                         f.path + ": grids '" + first + "' and '" + names[i] +
                             "' have different transforms (voxel size " + std::to_string(h0) +
                             " vs " + std::to_string(h) + ", index (0,0,0) at " + fmt_vec(t0) +
                             " vs " + fmt_vec(t) + "); they cannot be read onto one index box");
            }
            CoordBBox b;
            try {
                b = default_box(*g, f.path, false);
            } catch (const Fail &) {
                auto full = f.read(names[i]);
                b = full->evalActiveVoxelBoundingBox();
            }
            all.expand(b);
        }
        if (all.empty())
            fail(HV_ERR_INVALID_ARG, f.path + ": the grids have no active voxels");
        for (int a = 0; a < 3; a++) {
            lo[a] = all.min()[a];
            hi[a] = all.max()[a];
        }
        return HV_OK;
    });
}

hv_status hv_vdb_read_meta(const char *path, const char *grid_name, const char *key, char *buf,
                           size_t bufsize)
{
    return guarded(path ? path : "hv_vdb_read_meta", [&] {
        if (!key || !buf || bufsize == 0)
            fail(HV_ERR_INVALID_ARG, "hv_vdb_read_meta: key and buf are required");
        buf[0] = '\0';
        OpenFile f(path);
        openvdb::Metadata::Ptr m;
        if (grid_name) {
            f.require(grid_name);
            auto g = f.file.readGridMetadata(grid_name);
            m = (*g)[key];
        } else {
            auto fm = f.file.getMetadata();
            m = (*fm)[key];
        }
        if (!m)
            fail(HV_ERR_INVALID_ARG, f.path + ": no metadata '" + key + "' on " +
                                         (grid_name ? "grid '" + std::string(grid_name) + "'"
                                                    : std::string("the file")));
        snprintf(buf, bufsize, "%s", m->str().c_str());
        return HV_OK;
    });
}

} // extern "C"
