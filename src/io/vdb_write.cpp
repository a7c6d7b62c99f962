// The OpenVDB writer behind include/heatvox/vdb.h: dense heatvox grids become
// sparse OpenVDB grids (level sets, float, vec3, masks) built leaf by leaf,
// written with their metadata through a temporary file.
#include "heatvox/vdb.h"
#include "heatvox/io.h"
#include "vdb_internal.h"
#include "vdb_packed.h"

#include <openvdb/openvdb.h>
#include <openvdb/io/Archive.h>
#include <openvdb/io/io.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <limits>
#include <memory>
#include <string>
#include <vector>

using namespace hv_vdb_shim;

namespace
{

using openvdb::Coord;
using openvdb::Vec3d;
using openvdb::Vec3f;
using openvdb::Vec3i;

// ---- grid geometry ----------------------------------------------------------

// A uniform transform of voxel size h. OpenVDB's scale maps refuse a
// determinant h^3 below 3 times its double tolerance (1e-15): h under about
// 1.44e-5 in the mesh's units.
openvdb::math::Transform::Ptr linear_transform(double h)
{
    const double cube = 3.0 * openvdb::math::Tolerance<double>::value();
    if (!(h * h * h >= cube)) {
        char msg[256];
        std::snprintf(msg, sizeof msg,
                      "voxel size %.4g is below the smallest an OpenVDB transform takes (%.3g, "
                      "its cube %.0e): a coarser grid, or the input in larger units",
                      h, std::cbrt(cube), cube);
        fail(HV_ERR_INVALID_ARG, msg);
    }
    return openvdb::math::Transform::createLinearTransform(h);
}

// Index (i,j,k) maps to the cell centre origin + (i+1/2)h.
openvdb::math::Transform::Ptr make_transform(double h, const double origin[3])
{
    auto xf = linear_transform(h);
    xf->postTranslate(Vec3d(origin[0] + 0.5 * h, origin[1] + 0.5 * h, origin[2] + 0.5 * h));
    return xf;
}

// Where a dense block goes in index space: block voxel (i,j,k) is written at
// index (i,j,k) + off, under transform xf.
struct Placement {
    int off[3] = {0, 0, 0};
    openvdb::math::Transform::Ptr xf;
};

void check_grid(const hv_grid *g, const char *what)
{
    if (!g || !g->v)
        fail(HV_ERR_INVALID_ARG, std::string(what) + " is NULL");
    if (g->dim != 2 && g->dim != 3)
        fail(HV_ERR_INVALID_ARG, std::string(what) + ": dimension must be 2 or 3");
    for (int a = 0; a < 3; a++)
        if (g->n[a] <= 0 || !std::isfinite(g->origin[a]))
            fail(HV_ERR_INVALID_ARG, std::string(what) + ": bad size or origin");
    if (!(g->h > 0) || !std::isfinite(g->h))
        fail(HV_ERR_INVALID_ARG, std::string(what) + ": voxel size must be positive");
}

void check_same_shape(const hv_grid *a, const hv_grid *b, const char *an, const char *bn)
{
    bool same = a->n[0] == b->n[0] && a->n[1] == b->n[1] && a->n[2] == b->n[2] &&
                std::fabs(a->h - b->h) <= 1e-12 * a->h;
    for (int d = 0; d < 3 && same; d++)
        same = std::fabs(a->origin[d] - b->origin[d]) <= 1e-9 * (a->h + std::fabs(a->origin[d]));
    if (!same) {
        char buf[512];
        snprintf(
            buf, sizeof buf,
            "%s (%d x %d x %d, h %g, origin %g %g %g) and %s (%d x %d x %d, h %g, origin %g %g "
            "%g) must have the same size, voxel size and origin",
            an, a->n[0], a->n[1], a->n[2], a->h, a->origin[0], a->origin[1], a->origin[2], bn,
            b->n[0], b->n[1], b->n[2], b->h, b->origin[0], b->origin[1], b->origin[2]);
        fail(HV_ERR_INVALID_ARG, buf);
    }
}

inline size_t lin(const hv_grid *g, int i, int j, int k)
{
    return (size_t)i + (size_t)g->n[0] * ((size_t)j + (size_t)g->n[1] * (size_t)k);
}

// Builds a tree over the block [0,n) leaf by leaf. value(i,j,k, &active) gives
// each block voxel; the voxels of boundary leaves beyond the block are
// inactive and hold outside(i,j,k) of the nearest block voxel (the background,
// or for a level set the background with that voxel's sign, so that the sign
// stays continuous across the block's faces). Constant leaves are then
// collapsed into tiles by tools::prune (tolerance 0, lossless).
int floor_div(int a, int d) { return a >= 0 ? a / d : -((-a + d - 1) / d); }

template <class GridT, class F, class G>
void fill_block(GridT &grid, const int n[3], const int off[3], F &&value, G &&outside, bool prune)
{
    using LeafT = typename GridT::TreeType::LeafNodeType;
    using ValueT = typename GridT::ValueType;
    const int D = (int)LeafT::DIM;
    // Leaves cover the index box [off, off + n), aligned to multiples of D.
    int l0[3];
    size_t L[3];
    for (int a = 0; a < 3; a++) {
        l0[a] = floor_div(off[a], D);
        L[a] = (size_t)(floor_div(off[a] + n[a] - 1, D) - l0[a] + 1);
    }
    const size_t nleaf = L[0] * L[1] * L[2];
    auto origin = [&](size_t l) {
        return Coord((l0[0] + (int)(l % L[0])) * D, (l0[1] + (int)(l / L[0] % L[1])) * D,
                     (l0[2] + (int)(l / L[0] / L[1])) * D);
    };
    // Leaves are built in parallel; a leaf-sized region with no active voxel
    // and one value becomes a tile instead of a leaf.
    std::vector<std::unique_ptr<LeafT>> leaves(nleaf);
    std::vector<ValueT> tiles(nleaf);
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, nleaf), [&](const tbb::blocked_range<size_t> &r) {
            std::vector<ValueT> vals(LeafT::SIZE);
            std::vector<char> on(LeafT::SIZE);
            for (size_t l = r.begin(); l != r.end(); l++) {
                const Coord o = origin(l);
                bool any_on = false;
                for (int x = o[0]; x < o[0] + D; x++)
                    for (int y = o[1]; y < o[1] + D; y++)
                        for (int z = o[2]; z < o[2] + D; z++) {
                            const openvdb::Index q = LeafT::coordToOffset(Coord(x, y, z));
                            const int bi = x - off[0], bj = y - off[1], bk = z - off[2];
                            const int i = std::clamp(bi, 0, n[0] - 1),
                                      j = std::clamp(bj, 0, n[1] - 1),
                                      k = std::clamp(bk, 0, n[2] - 1);
                            bool active = false;
                            if (bi == i && bj == j && bk == k)
                                vals[q] = value(i, j, k, &active);
                            else
                                vals[q] = outside(i, j, k);
                            on[q] = active;
                            any_on |= active;
                        }
                bool uniform = !any_on;
                for (size_t q = 1; uniform && q < vals.size(); q++)
                    uniform = vals[q] == vals[0];
                if (uniform) {
                    tiles[l] = vals[0];
                    continue;
                }
                auto leaf = std::make_unique<LeafT>(o, vals[0], false);
                for (openvdb::Index q = 0; q < LeafT::SIZE; q++) {
                    if (on[q])
                        leaf->setValueOn(q, vals[q]);
                    else
                        leaf->setValueOff(q, vals[q]);
                }
                leaves[l] = std::move(leaf);
            }
        });
    auto &tree = grid.tree();
    for (size_t l = 0; l < nleaf; l++) {
        if (leaves[l])
            tree.addLeaf(leaves[l].release());
        else
            tree.addTile(1, origin(l), tiles[l], false);
    }
    if (prune)
        openvdb::tools::prune(tree);
}

void tag_block(openvdb::GridBase &grid, const int n[3], const int off[3])
{
    grid.insertMeta(BLOCK_MIN, openvdb::Vec3IMetadata(Vec3i(off[0], off[1], off[2])));
    grid.insertMeta(BLOCK_MAX, openvdb::Vec3IMetadata(
                                   Vec3i(off[0] + n[0] - 1, off[1] + n[1] - 1, off[2] + n[2] - 1)));
}

openvdb::FloatGrid::Ptr levelset_from(const hv_grid *g, double band_voxels, bool dense, bool prune,
                                      const Placement &pl = Placement())
{
    const float bg = (float)(band_voxels * g->h);
    auto grid = openvdb::FloatGrid::create(bg);
    const float *v = g->v;
    fill_block(
        *grid, g->n, pl.off,
        [&](int i, int j, int k, bool *active) {
            float p = v[lin(g, i, j, k)];
            *active = dense || std::fabs(p) < bg;
            if (*active)
                return p;
            return p < 0 ? -bg : bg;
        },
        [&](int i, int j, int k) { return v[lin(g, i, j, k)] < 0 ? -bg : bg; }, prune);
    grid->setTransform(pl.xf ? pl.xf : make_transform(g->h, g->origin));
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    return grid;
}

} // namespace

namespace
{
struct LevelsetStream;
}

struct hv_vdb_writer {
    openvdb::GridPtrVec grids;
    std::unique_ptr<LevelsetStream> stream; // hv_vdb_writer_levelset_sink's grid under way
    openvdb::MetaMap meta;
    bool has_index0 = false; // hv_vdb_writer_set_index_origin was called
    double index0[3] = {0, 0, 0};
};

namespace
{

void check_new_name(hv_vdb_writer *w, const char *name)
{
    if (!w)
        fail(HV_ERR_INVALID_ARG, "vdb writer is NULL");
    if (!name || !*name)
        fail(HV_ERR_INVALID_ARG, "vdb writer: grid name is empty");
    for (auto &g : w->grids)
        if (g->getName() == name)
            fail(HV_ERR_INVALID_ARG,
                 std::string("vdb writer: a grid named '") + name + "' was already added");
}

// Block g's index offset in this writer's index space: 0 by default; after
// hv_vdb_writer_set_index_origin, the whole voxels that keep the block's
// world position with index (0,0,0) at that origin.
void index_offset(const hv_vdb_writer *w, const hv_grid *g, const char *name, int off[3])
{
    for (int a = 0; a < 3; a++) {
        off[a] = 0;
        if (!w->has_index0)
            continue;
        double s = (g->origin[a] + 0.5 * g->h - w->index0[a]) / g->h;
        double r = std::nearbyint(s);
        if (!(std::fabs(s - r) <= 1e-4) || std::fabs(r) > 1e9) {
            char msg[256];
            std::snprintf(msg, sizeof msg,
                          "grid '%s': its voxels are not on the index lattice of the writer's "
                          "index origin (axis %d is %.6g voxels off)",
                          name, a, s - r);
            fail(HV_ERR_INVALID_ARG, msg);
        }
        off[a] = (int)r;
    }
}

// The placement of block g in this writer's index space: by default index
// (0,0,0) is the block's first voxel; after hv_vdb_writer_set_index_origin the
// transform puts index (0,0,0) at that world position and the block is shifted
// by whole voxels to keep its world position.
Placement placement(const hv_vdb_writer *w, const hv_grid *g, const char *name)
{
    Placement pl;
    index_offset(w, g, name, pl.off);
    if (!w->has_index0) {
        pl.xf = make_transform(g->h, g->origin);
        return pl;
    }
    pl.xf = linear_transform(g->h);
    pl.xf->postTranslate(Vec3d(w->index0[0], w->index0[1], w->index0[2]));
    return pl;
}

bool on_leaf_lattice(const int off[3])
{
    return off[0] % 8 == 0 && off[1] % 8 == 0 && off[2] % 8 == 0;
}

void finish_grid(hv_vdb_writer *w, openvdb::GridBase::Ptr grid, const hv_grid *g, const char *name,
                 const Placement &pl)
{
    grid->setName(name);
    grid->setSaveFloatAsHalf(false);
    grid->setCreator(std::string("heatvox ") + HV_VERSION_STRING);
    tag_block(*grid, g->n, pl.off);
    w->grids.push_back(grid);
}

// ---- tiles --------------------------------------------------------------------

constexpr size_t TILE_CELLS = HV_TILE * HV_TILE * HV_TILE;

// Checks tiles t (`what` names them in messages) and returns their block as a
// grid without values, for placement() and finish_grid().
hv_grid tiles_block(const hv_tiles *t, const std::string &what)
{
    if (!t || (t->count && (!t->ijk || !t->v || !t->on)))
        fail(HV_ERR_INVALID_ARG, what + ": tiles are NULL");
    hv_grid b = {};
    b.dim = 3;
    b.h = t->h;
    for (int a = 0; a < 3; a++) {
        b.n[a] = t->n[a];
        b.origin[a] = t->origin[a];
    }
    float unused = 0;
    b.v = &unused; // check_grid requires values; nothing reads them
    check_grid(&b, what.c_str());
    b.v = nullptr;
    for (size_t q = 0; q < t->count; q++)
        for (int a = 0; a < 3; a++) {
            const int32_t c = t->ijk[3 * q + a];
            if (c % HV_TILE || c < 0 || c >= t->n[a])
                fail(HV_ERR_INVALID_ARG, what + ": a tile is not on the block's 8^3 lattice");
        }
    return b;
}

// HV_ERR_NUMERIC naming the grid for a NaN or Inf on a voxel active in `on`
// (inactive voxels are not written).
void check_active_finite(const hv_tiles *on, const hv_tiles *t, const std::string &what)
{
    const size_t none = std::numeric_limits<size_t>::max();
    const size_t bad = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, t->count), none,
        [&](const tbb::blocked_range<size_t> &r, size_t first) {
            for (size_t q = r.begin(); q != r.end() && first == none; q++)
                for (int k = 0; k < HV_TILE && first == none; k++)
                    for (uint64_t m = on->on[HV_TILE * q + k]; m; m &= m - 1) {
                        const size_t c = q * TILE_CELLS + HV_TILE * HV_TILE * (size_t)k +
                                         (size_t)__builtin_ctzll(m);
                        if (!std::isfinite(t->v[c])) {
                            first = c;
                            break;
                        }
                    }
            return first;
        },
        [](size_t a, size_t b) { return std::min(a, b); });
    if (bad == none)
        return;
    const size_t q = bad / TILE_CELLS, c = bad % TILE_CELLS;
    char buf[160];
    snprintf(buf, sizeof buf, " holds a non-finite value (%g) at block cell (%d, %d, %d)",
             (double)t->v[bad], t->ijk[3 * q] + (int)(c % HV_TILE),
             t->ijk[3 * q + 1] + (int)(c / HV_TILE % HV_TILE),
             t->ijk[3 * q + 2] + (int)(c / (HV_TILE * HV_TILE)));
    fail(HV_ERR_NUMERIC, what + buf);
}

// Adds the voxels active in tiles t to grid, at index = block index + off,
// with value(index into t->v); inactive voxels hold the background and stay
// inactive. Leaves are built in parallel. Unless off is a multiple of 8 a
// tile meets up to 8 leaves and a leaf up to 8 tiles, so each leaf is built
// from its (leaf, tile) pairs, sorted by leaf.
template <class GridT, class F>
void add_active_voxels(GridT &grid, const hv_tiles *t, const int off[3], F &&value)
{
    using LeafT = typename GridT::TreeType::LeafNodeType;
    const int D = (int)LeafT::DIM;
    struct Part {
        Coord leaf;
        size_t q;
    };
    std::vector<Part> parts;
    for (size_t q = 0; q < t->count; q++) {
        uint64_t any = 0;
        for (int k = 0; k < HV_TILE; k++)
            any |= t->on[HV_TILE * q + k];
        if (!any)
            continue;
        const int32_t *c = t->ijk + 3 * q;
        const Coord T(c[0] + off[0], c[1] + off[1], c[2] + off[2]);
        // T & ~(D-1) rounds down to the leaf lattice, negatives included.
        for (int lz = T[2] & ~(D - 1); lz < T[2] + HV_TILE; lz += D)
            for (int ly = T[1] & ~(D - 1); ly < T[1] + HV_TILE; ly += D)
                for (int lx = T[0] & ~(D - 1); lx < T[0] + HV_TILE; lx += D)
                    parts.push_back(Part{Coord(lx, ly, lz), q});
    }
    tbb::parallel_sort(parts.begin(), parts.end(), [](const Part &a, const Part &b) {
        return a.leaf < b.leaf || (a.leaf == b.leaf && a.q < b.q);
    });
    std::vector<size_t> first; // each leaf's first part, then parts.size()
    for (size_t p = 0; p < parts.size(); p++)
        if (p == 0 || parts[p].leaf != parts[p - 1].leaf)
            first.push_back(p);
    first.push_back(parts.size());
    const size_t nleaf = first.size() - 1;
    std::vector<std::unique_ptr<LeafT>> leaves(nleaf);
    const auto bg = grid.background();
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, nleaf), [&](const tbb::blocked_range<size_t> &r) {
            for (size_t l = r.begin(); l != r.end(); l++) {
                const Coord L = parts[first[l]].leaf;
                auto leaf = std::make_unique<LeafT>(L, bg, false);
                for (size_t p = first[l]; p < first[l + 1]; p++) {
                    const size_t q = parts[p].q;
                    const int32_t *c = t->ijk + 3 * q;
                    const Coord T(c[0] + off[0], c[1] + off[1], c[2] + off[2]);
                    int b0[3], b1[3]; // the overlap, in tile cells
                    for (int a = 0; a < 3; a++) {
                        b0[a] = std::max(L[a], T[a]) - T[a];
                        b1[a] = std::min(L[a] + D, T[a] + HV_TILE) - T[a];
                    }
                    for (int k = b0[2]; k < b1[2]; k++)
                        for (int j = b0[1]; j < b1[1]; j++)
                            for (int i = b0[0]; i < b1[0]; i++)
                                if (t->on[HV_TILE * q + k] >> (i + HV_TILE * j) & 1)
                                    leaf->setValueOn(
                                        LeafT::coordToOffset(T.offsetBy(i, j, k)),
                                        value(q * TILE_CELLS +
                                              (size_t)(i + HV_TILE * (j + HV_TILE * k))));
                }
                if (!leaf->isEmpty())
                    leaves[l] = std::move(leaf);
            }
        });
    auto &tree = grid.tree();
    for (auto &l : leaves)
        if (l)
            tree.addLeaf(l.release());
}

// A level set's band width in voxels: positive and finite.
void check_band(const char *name, double band_voxels)
{
    if (!(band_voxels > 0) || !std::isfinite(band_voxels))
        fail(HV_ERR_INVALID_ARG, std::string("level set '") + name +
                                     "': band width must be positive, got " +
                                     std::to_string(band_voxels));
}

// Adds the voxels of tiles t active with |value| < bg to grid at index offset
// off; the others of a tile hold bg, inactive, for the flood fill. A tile of
// the block (at a multiple of 8) is one leaf when off is a multiple of 8 too,
// built in parallel and packed at once when the grid packs; otherwise it
// spans up to 8, which an accessor touches (a leaf may then take voxels from
// later batches, so none is packed).
void add_band_leaves(LevelsetGrid &grid, const hv_tiles *t, const int off[3], float bg)
{
    const bool aligned = on_leaf_lattice(off);
    auto voxel = [&](size_t q, int i, int j, int k, float *val) {
        const int o = i + HV_TILE * (j + HV_TILE * k);
        *val = t->v[q * HV_TILE * HV_TILE * HV_TILE + o];
        bool on = t->on[8 * q + k] >> (i + HV_TILE * j) & 1;
        return on && std::fabs(*val) < bg;
    };
    if (!aligned) {
        if (grid.packed_leaves())
            fail(HV_ERR_INTERNAL, "level set: tiles off the leaf lattice for a packed grid");
        auto acc = grid.getAccessor();
        for (size_t q = 0; q < t->count; q++) {
            const int32_t *c = t->ijk + 3 * q;
            for (int k = 0; k < HV_TILE; k++)
                for (int j = 0; j < HV_TILE; j++)
                    for (int i = 0; i < HV_TILE; i++) {
                        float val;
                        if (voxel(q, i, j, k, &val))
                            acc.setValueOn(
                                Coord(c[0] + i + off[0], c[1] + j + off[1], c[2] + k + off[2]),
                                val);
                    }
        }
        return;
    }
    const bool pack = grid.packing();
    const size_t id0 = pack ? grid.reserve_packed(t->count) : 0;
    std::vector<std::unique_ptr<FloatLeaf>> leaves(t->count);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, t->count),
                      [&](const tbb::blocked_range<size_t> &r) {
                          std::ostringstream ss = grid.packing_stream();
                          for (size_t q = r.begin(); q != r.end(); q++) {
                              const int32_t *c = t->ijk + 3 * q;
                              Coord o(c[0] + off[0], c[1] + off[1], c[2] + off[2]);
                              auto leaf = std::make_unique<FloatLeaf>(o, bg, false);
                              for (int k = 0; k < HV_TILE; k++)
                                  for (int j = 0; j < HV_TILE; j++)
                                      for (int i = 0; i < HV_TILE; i++) {
                                          float val;
                                          Coord x = o.offsetBy(i, j, k);
                                          if (voxel(q, i, j, k, &val))
                                              leaf->setValueOn(x, val);
                                          else
                                              leaf->setValueOff(x, bg);
                                      }
                              if (pack)
                                  grid.pack(*leaf, id0 + q, ss);
                              leaves[q] = std::move(leaf);
                          }
                      });
    auto &tree = grid.tree();
    for (auto &l : leaves)
        tree.addLeaf(l.release());
}

// The level set's last steps: inactive voxels and tiles take the sign of the
// active voxels around them, as in OpenVDB's own mesh-to-level-set
// conversion; then its transform, class and name.
void finish_levelset(hv_vdb_writer *w, LevelsetGrid::Ptr grid, const hv_grid *hdr, const char *name,
                     const Placement &pl)
{
    grid->flood_fill();
    grid->setTransform(pl.xf);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    finish_grid(w, grid, hdr, name, pl);
}

// ---- a level set streamed from tiles --------------------------------------

// The grid hv_vdb_writer_levelset_sink builds from the batches it is handed.
struct LevelsetStream {
    hv_vdb_writer *w;
    std::string name;
    double band_voxels;
    hv_vdb_sink_stats *stats; // may be NULL
    hv_vdb_sink_stats S{};
    hv_grid hdr{};
    Placement pl;
    float bg = 0;
    LevelsetGrid::Ptr grid;
};

// A bound on the memory of a float tree of `leaves` leaves on block n, the
// leaves' values aside: the leaves; a 16^3-leaf node for every 128 leaves (a
// surface through such a node fills 300 to 500 of its leaves); and every
// 32^3-node node the block can meet.
double topology_bytes(double leaves, const int n[3])
{
    using Node1 = openvdb::FloatTree::RootNodeType::ChildNodeType::ChildNodeType;
    using Node2 = openvdb::FloatTree::RootNodeType::ChildNodeType;
    double top = 1;
    for (int a = 0; a < 3; a++)
        top *= n[a] / (double)Node2::DIM + 2;
    return leaves * (double)sizeof(FloatLeaf) + (leaves / 128 + 1) * (double)sizeof(Node1) +
           top * (double)sizeof(Node2);
}

// What a leaf's values take: all of them (2 kB) unpacked; packed, an estimate
// of its bytes for a band of w voxels each side: the value mask, the
// mask-compression header (up to a selection mask), the array's size and
// 4 bytes for each active voxel, of which a leaf holds 64 w on average
// (190 at w = 3 on the bunny from 256^3 to 8192^3; Blosc saves about a tenth
// of them) and a quarter more are allowed for; then the string, its
// allocation and the growth of the vector of strings.
double leaf_value_bytes(bool packed, double w)
{
    if (!packed)
        return FloatLeaf::SIZE * sizeof(float);
    const double active = std::min((double)FloatLeaf::SIZE, 1.25 * 64 * w);
    const double mask = FloatLeaf::NodeMaskType::memUsage();
    return 2 * mask + 1 + 2 * sizeof(float) + 8 + active * sizeof(float) + 16 +
           2 * sizeof(std::string);
}

hv_status stream_begin(void *user, const hv_tiles *block, size_t max_tiles)
{
    auto *ls = static_cast<LevelsetStream *>(user);
    return guarded("hv_vdb_writer_levelset_sink", [&] {
        const std::string what = "level set '" + ls->name + "'";
        ls->hdr = tiles_block(block, what);
        int off[3];
        index_offset(ls->w, &ls->hdr, ls->name.c_str(), off);
        const bool pack = LevelsetGrid::can_pack() && on_leaf_lattice(off);
        const double leaves = (double)max_tiles;
        const double need =
            topology_bytes(leaves, block->n) + leaves * leaf_value_bytes(pack, ls->band_voxels);
        if (need > (double)hv__memory_limit(nullptr)) {
            char msg[256], lim[96];
            std::snprintf(msg, sizeof msg,
                          ": its tree of up to %zu leaves needs about %.3g GB, more than %s",
                          max_tiles, need / 1e9, hv__memory_limit_text(lim, sizeof lim));
            fail(HV_ERR_NOMEM, what + msg);
        }
        ls->pl = placement(ls->w, &ls->hdr, ls->name.c_str());
        ls->bg = (float)(ls->band_voxels * block->h);
        ls->grid = std::make_shared<LevelsetGrid>(ls->bg, pack);
        ls->S.tree_bytes_bound = need;
        return HV_OK;
    });
}

hv_status stream_put(void *user, const hv_tiles *batch)
{
    auto *ls = static_cast<LevelsetStream *>(user);
    return guarded("hv_vdb_writer_levelset_sink", [&] {
        if (!ls->grid)
            fail(HV_ERR_INVALID_ARG, "level set '" + ls->name + "': tiles came before begin");
        const std::string what = "level set '" + ls->name + "'";
        const hv_grid b = tiles_block(batch, what);
        for (int k = 0; k < 3; k++)
            if (b.n[k] != ls->hdr.n[k] || b.origin[k] != ls->hdr.origin[k] || b.h != ls->hdr.h)
                fail(HV_ERR_INVALID_ARG, what + ": a batch of tiles on another block than begin's");
        hv_status st = hv_check_finite(
            batch->v, batch->count * (size_t)(HV_TILE * HV_TILE * HV_TILE), ls->name.c_str());
        if (st)
            return st;
        const double t0 = hv_now();
        add_band_leaves(*ls->grid, batch, ls->pl.off, ls->bg);
        ls->S.t_leaves += hv_now() - t0;
        ls->S.batches++;
        ls->S.tiles += batch->count;
        return HV_OK;
    });
}

hv_status stream_end(void *user, int ok)
{
    auto *ls = static_cast<LevelsetStream *>(user);
    hv_vdb_writer *w = ls->w;
    hv_status st = HV_OK;
    if (ok && ls->grid)
        st = guarded("hv_vdb_writer_levelset_sink", [&] {
            const double t0 = hv_now();
            check_new_name(w, ls->name.c_str());
            finish_levelset(w, ls->grid, &ls->hdr, ls->name.c_str(), ls->pl);
            ls->S.t_fill = hv_now() - t0;
            ls->S.leaves = ls->grid->tree().leafCount();
            ls->S.tree_bytes = (double)ls->grid->tree().memUsage();
            ls->S.packed_leaves = ls->grid->packed_leaves();
            ls->S.packed_bytes = ls->grid->packed_bytes();
            return HV_OK;
        });
    if (ls->stats)
        *ls->stats = ls->S;
    w->stream.reset(); // ls is gone
    return st;
}

} // namespace

extern "C" {

hv_status hv_vdb_writer_create(hv_vdb_writer **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_vdb_writer_create: out is NULL");
    *out = nullptr;
    return guarded("hv_vdb_writer_create", [&] {
        init_vdb();
        auto *w = new hv_vdb_writer;
        w->meta.insertMeta("creator",
                           openvdb::StringMetadata(std::string("heatvox ") + HV_VERSION_STRING));
        *out = w;
        return HV_OK;
    });
}

void hv_vdb_writer_destroy(hv_vdb_writer **w)
{
    if (!w || !*w)
        return;
    delete *w;
    *w = nullptr;
}

hv_status hv_vdb_writer_add_levelset(hv_vdb_writer *w, const hv_grid *g, const char *name,
                                     double band_voxels, int dense)
{
    return guarded("hv_vdb_writer_add_levelset", [&] {
        check_new_name(w, name);
        check_grid(g, "level set grid");
        if (!(band_voxels > 0) || !std::isfinite(band_voxels))
            fail(HV_ERR_INVALID_ARG, std::string("level set '") + name +
                                         "': band width must be positive, got " +
                                         std::to_string(band_voxels));
        hv_status st = hv_check_finite(g->v, hv_grid_count(g), name);
        if (st)
            return st;
        Placement pl = placement(w, g, name);
        auto grid = levelset_from(g, band_voxels, dense != 0, true, pl);
        finish_grid(w, grid, g, name, pl);
        return HV_OK;
    });
}

hv_status hv_vdb_writer_add_levelset_tiles(hv_vdb_writer *w, const hv_tiles *t, const char *name,
                                           double band_voxels)
{
    return guarded("hv_vdb_writer_add_levelset_tiles", [&] {
        check_new_name(w, name);
        const hv_grid hdr = tiles_block(t, std::string("level set '") + name + "'");
        check_band(name, band_voxels);
        hv_status st =
            hv_check_finite(t->v, t->count * (size_t)(HV_TILE * HV_TILE * HV_TILE), name);
        if (st)
            return st;
        Placement pl = placement(w, &hdr, name);
        const float bg = (float)(band_voxels * t->h);
        auto grid = std::make_shared<LevelsetGrid>(bg, on_leaf_lattice(pl.off));
        add_band_leaves(*grid, t, pl.off, bg);
        finish_levelset(w, grid, &hdr, name, pl);
        return HV_OK;
    });
}

hv_status hv_vdb_writer_levelset_sink(hv_vdb_writer *w, const char *name, double band_voxels,
                                      hv_vdb_sink_stats *stats, hv_tiles_sink *out)
{
    return guarded("hv_vdb_writer_levelset_sink", [&] {
        if (!out)
            fail(HV_ERR_INVALID_ARG, "hv_vdb_writer_levelset_sink: out is NULL");
        *out = hv_tiles_sink{};
        check_new_name(w, name);
        check_band(name, band_voxels);
        if (w->stream)
            fail(HV_ERR_INVALID_ARG, std::string("level set '") + name +
                                         "': the writer is still taking level set '" +
                                         w->stream->name + "'");
        auto ls = std::make_unique<LevelsetStream>();
        ls->w = w;
        ls->name = name;
        ls->band_voxels = band_voxels;
        ls->stats = stats;
        *out = hv_tiles_sink{ls.get(), stream_begin, stream_put, stream_end};
        w->stream = std::move(ls);
        return HV_OK;
    });
}

hv_status hv_vdb_writer_add_float(hv_vdb_writer *w, const hv_grid *g, const char *name)
{
    return guarded("hv_vdb_writer_add_float", [&] {
        check_new_name(w, name);
        check_grid(g, "float grid");
        Placement pl = placement(w, g, name);
        auto grid = openvdb::FloatGrid::create(0.0f);
        fill_block(
            *grid, g->n, pl.off,
            [&](int i, int j, int k, bool *active) {
                *active = true;
                return g->v[lin(g, i, j, k)];
            },
            [](int, int, int) { return 0.0f; }, true);
        grid->setTransform(pl.xf);
        grid->setGridClass(openvdb::GRID_UNKNOWN);
        finish_grid(w, grid, g, name, pl);
        return HV_OK;
    });
}

hv_status hv_vdb_writer_add_fog(hv_vdb_writer *w, const hv_grid *g, const char *name)
{
    return guarded("hv_vdb_writer_add_fog", [&] {
        check_new_name(w, name);
        check_grid(g, "fog volume");
        hv_status st = hv_check_finite(g->v, hv_grid_count(g), name);
        if (st)
            return st;
        Placement pl = placement(w, g, name);
        auto grid = openvdb::FloatGrid::create(0.0f);
        const double inv_h = 1.0 / g->h;
        fill_block(
            *grid, g->n, pl.off,
            [&](int i, int j, int k, bool *active) {
                const float d = (float)std::clamp(0.5 - g->v[lin(g, i, j, k)] * inv_h, 0.0, 1.0);
                *active = d > 0;
                return d;
            },
            [](int, int, int) { return 0.0f; }, true);
        grid->setTransform(pl.xf);
        grid->setGridClass(openvdb::GRID_FOG_VOLUME);
        finish_grid(w, grid, g, name, pl);
        return HV_OK;
    });
}

hv_status hv_vdb_writer_add_vec3(hv_vdb_writer *w, const hv_grid *gx, const hv_grid *gy,
                                 const hv_grid *gz, const char *name)
{
    return guarded("hv_vdb_writer_add_vec3", [&] {
        check_new_name(w, name);
        check_grid(gx, "x component");
        check_grid(gy, "y component");
        check_grid(gz, "z component");
        check_same_shape(gx, gy, "x component", "y component");
        check_same_shape(gx, gz, "x component", "z component");
        Placement pl = placement(w, gx, name);
        auto grid = openvdb::Vec3SGrid::create(Vec3f(0, 0, 0));
        fill_block(
            *grid, gx->n, pl.off,
            [&](int i, int j, int k, bool *active) {
                *active = true;
                size_t c = lin(gx, i, j, k);
                return Vec3f(gx->v[c], gy->v[c], gz->v[c]);
            },
            [](int, int, int) { return Vec3f(0, 0, 0); }, true);
        grid->setTransform(pl.xf);
        grid->setGridClass(openvdb::GRID_UNKNOWN);
        grid->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
        finish_grid(w, grid, gx, name, pl);
        return HV_OK;
    });
}

hv_status hv_vdb_writer_add_float_tiles(hv_vdb_writer *w, const hv_tiles *t, const char *name)
{
    return guarded("hv_vdb_writer_add_float_tiles", [&] {
        check_new_name(w, name);
        const std::string what = std::string("float grid '") + name + "'";
        const hv_grid b = tiles_block(t, what);
        check_active_finite(t, t, what);
        Placement pl = placement(w, &b, name);
        auto grid = openvdb::FloatGrid::create(0.0f);
        const float *v = t->v;
        add_active_voxels(*grid, t, pl.off, [v](size_t c) { return v[c]; });
        openvdb::tools::prune(grid->tree());
        grid->setTransform(pl.xf);
        grid->setGridClass(openvdb::GRID_UNKNOWN);
        finish_grid(w, grid, &b, name, pl);
        return HV_OK;
    });
}

hv_status hv_vdb_writer_add_vec3_tiles(hv_vdb_writer *w, const hv_tiles *tx, const hv_tiles *ty,
                                       const hv_tiles *tz, const char *name)
{
    return guarded("hv_vdb_writer_add_vec3_tiles", [&] {
        check_new_name(w, name);
        const std::string what = std::string("vec3 grid '") + name + "'";
        const hv_grid bx = tiles_block(tx, what + " x tiles");
        const hv_grid by = tiles_block(ty, what + " y tiles");
        const hv_grid bz = tiles_block(tz, what + " z tiles");
        check_same_shape(&bx, &by, "x tiles", "y tiles");
        check_same_shape(&bx, &bz, "x tiles", "z tiles");
        const size_t ijk_bytes = 3 * tx->count * sizeof *tx->ijk;
        if (ty->count != tx->count || tz->count != tx->count ||
            (tx->count &&
             (memcmp(ty->ijk, tx->ijk, ijk_bytes) || memcmp(tz->ijk, tx->ijk, ijk_bytes))))
            fail(HV_ERR_INVALID_ARG,
                 what + ": the x, y and z tiles must be the same tiles in the same order");
        check_active_finite(tx, tx, what + " x component");
        check_active_finite(tx, ty, what + " y component");
        check_active_finite(tx, tz, what + " z component");
        Placement pl = placement(w, &bx, name);
        auto grid = openvdb::Vec3SGrid::create(Vec3f(0, 0, 0));
        const float *x = tx->v, *y = ty->v, *z = tz->v;
        add_active_voxels(*grid, tx, pl.off,
                          [x, y, z](size_t c) { return Vec3f(x[c], y[c], z[c]); });
        openvdb::tools::prune(grid->tree());
        grid->setTransform(pl.xf);
        grid->setGridClass(openvdb::GRID_UNKNOWN);
        grid->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
        finish_grid(w, grid, &bx, name, pl);
        return HV_OK;
    });
}

hv_status hv_vdb_writer_add_mask(hv_vdb_writer *w, const hv_grid *g, const char *name)
{
    return guarded("hv_vdb_writer_add_mask", [&] {
        check_new_name(w, name);
        check_grid(g, "mask grid");
        Placement pl = placement(w, g, name);
        auto grid = openvdb::BoolGrid::create(false);
        if (g->solid) {
            auto acc = grid->getAccessor();
            for (int k = 0; k < g->n[2]; k++)
                for (int j = 0; j < g->n[1]; j++)
                    for (int i = 0; i < g->n[0]; i++)
                        if (g->solid[lin(g, i, j, k)])
                            acc.setValueOn(Coord(i + pl.off[0], j + pl.off[1], k + pl.off[2]),
                                           true);
            openvdb::tools::prune(grid->tree());
        }
        grid->setTransform(pl.xf);
        finish_grid(w, grid, g, name, pl);
        return HV_OK;
    });
}

hv_status hv_vdb_writer_set_index_origin(hv_vdb_writer *w, const double index0_world[3])
{
    return guarded("hv_vdb_writer_set_index_origin", [&] {
        if (!w || !index0_world)
            fail(HV_ERR_INVALID_ARG,
                 "hv_vdb_writer_set_index_origin: writer and position are required");
        for (int a = 0; a < 3; a++)
            if (!std::isfinite(index0_world[a]))
                fail(HV_ERR_INVALID_ARG, "hv_vdb_writer_set_index_origin: position is not finite");
        w->has_index0 = true;
        for (int a = 0; a < 3; a++)
            w->index0[a] = index0_world[a];
        return HV_OK;
    });
}

hv_status hv_vdb_writer_set_meta(hv_vdb_writer *w, const char *key, const char *value)
{
    return guarded("hv_vdb_writer_set_meta", [&] {
        if (!w || !key || !*key || !value)
            fail(HV_ERR_INVALID_ARG, "hv_vdb_writer_set_meta: writer, key and value are required");
        w->meta.removeMeta(key);
        w->meta.insertMeta(key, openvdb::StringMetadata(value));
        return HV_OK;
    });
}

hv_status hv_vdb_writer_set_grid_meta(hv_vdb_writer *w, const char *grid_name, const char *key,
                                      const char *value)
{
    return guarded("hv_vdb_writer_set_grid_meta", [&] {
        if (!w || !grid_name || !key || !*key || !value)
            fail(HV_ERR_INVALID_ARG,
                 "hv_vdb_writer_set_grid_meta: writer, grid, key and value are required");
        for (auto &g : w->grids)
            if (g->getName() == grid_name) {
                g->removeMeta(key);
                g->insertMeta(key, openvdb::StringMetadata(value));
                return HV_OK;
            }
        fail(HV_ERR_INVALID_ARG, std::string("hv_vdb_writer_set_grid_meta: no grid named '") +
                                     grid_name + "' was added");
    });
}

hv_status hv_vdb_writer_write(hv_vdb_writer *w, const char *path)
{
    char tmp[4096];
    tmp[0] = '\0';
    hv_status st = guarded(path ? path : "hv_vdb_writer_write", [&] {
        if (!w)
            fail(HV_ERR_INVALID_ARG, "hv_vdb_writer_write: writer is NULL");
        if (!path || !*path)
            fail(HV_ERR_INVALID_ARG, "hv_vdb_writer_write: output path is empty");
        if (w->grids.empty())
            fail(HV_ERR_INVALID_ARG, std::string(path) + ": no grids were added to the writer");
        hv_status s = hv_tmp_name(path, tmp, sizeof tmp);
        if (s) {
            tmp[0] = '\0';
            return s;
        }
        std::ofstream os(tmp, std::ios_base::out | std::ios_base::binary | std::ios_base::trunc);
        if (!os)
            fail(HV_ERR_IO,
                 std::string(path) + ": cannot create the output file: " + strerror(errno));
        openvdb::GridCPtrVec grids(w->grids.begin(), w->grids.end());
        write_archive(os, grids, w->meta);
        os.flush();
        os.close();
        if (os.fail())
            fail(HV_ERR_IO, std::string(path) + ": writing failed (disk full?)");
        s = hv_tmp_commit(tmp, path);
        tmp[0] = '\0';
        return s;
    });
    if (st && tmp[0])
        hv_tmp_discard(tmp);
    return st;
}

} // extern "C"
