// The only C++ in heatvox: OpenVDB files and reference tools behind the C API of
// include/heatvox/vdb.h. Every entry point runs its body inside guarded(), which
// turns any exception into an hv_status with a message; nothing escapes into C.
#include "heatvox/vdb.h"
#include "heatvox/io.h"

extern "C" {
#include "core/error.h"
}
#include "io/vdb_check.h"

#include <openvdb/openvdb.h>
#include <openvdb/io/Archive.h>
#include <openvdb/io/File.h>
#include <openvdb/tools/FastSweeping.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/Prune.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <mutex>
#include <new>
#include <string>
#include <vector>

namespace {

using openvdb::Coord;
using openvdb::CoordBBox;
using openvdb::Vec3d;
using openvdb::Vec3f;
using openvdb::Vec3i;

const char *const BLOCK_MIN = "heatvox_block_min";
const char *const BLOCK_MAX = "heatvox_block_max";

// An error detected inside the shim, carried to the C boundary.
struct Fail {
    hv_status st;
    std::string msg;
};

[[noreturn]] void fail(hv_status st, const std::string &msg) { throw Fail{st, msg}; }

std::string fmt_vec(const Vec3d &v)
{
    char buf[128];
    snprintf(buf, sizeof buf, "(%.9g, %.9g, %.9g)", v[0], v[1], v[2]);
    return buf;
}

// `where` names the file or operation, so that OpenVDB's own messages (which
// often omit it) still say which input failed.
template <class F> hv_status guarded(const char *where, F &&body)
{
    try {
        return body();
    } catch (const Fail &e) {
        return hv_error(e.st, "%s", e.msg.c_str());
    } catch (const openvdb::IoError &e) {
        return hv_error(HV_ERR_IO, "%s: %s", where, e.what());
    } catch (const openvdb::Exception &e) {
        return hv_error(HV_ERR_BACKEND, "%s: OpenVDB: %s", where, e.what());
    } catch (const std::bad_alloc &) {
        return hv_error(HV_ERR_NOMEM, "%s: out of memory", where);
    } catch (const std::exception &e) {
        return hv_error(HV_ERR_BACKEND, "%s: %s", where, e.what());
    } catch (...) {
        return hv_error(HV_ERR_INTERNAL, "%s: unknown exception", where);
    }
}

std::once_flag init_flag;
void init_vdb()
{
    std::call_once(init_flag, [] { openvdb::initialize(); });
}

// ---- grid geometry ----------------------------------------------------------

// Index (i,j,k) maps to the cell centre origin + (i+1/2)h.
openvdb::math::Transform::Ptr make_transform(double h, const double origin[3])
{
    auto xf = openvdb::math::Transform::createLinearTransform(h);
    xf->postTranslate(
        Vec3d(origin[0] + 0.5 * h, origin[1] + 0.5 * h, origin[2] + 0.5 * h));
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
        snprintf(buf, sizeof buf,
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
void fill_block(GridT &grid, const int n[3], const int off[3], F &&value, G &&outside,
                bool prune)
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
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nleaf), [&](const tbb::blocked_range<size_t> &r) {
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
                        const int i = std::clamp(bi, 0, n[0] - 1), j = std::clamp(bj, 0, n[1] - 1),
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
    grid.insertMeta(BLOCK_MAX, openvdb::Vec3IMetadata(Vec3i(off[0] + n[0] - 1, off[1] + n[1] - 1,
                                                            off[2] + n[2] - 1)));
}

openvdb::FloatGrid::Ptr levelset_from(const hv_grid *g, double band_voxels, bool dense,
                                      bool prune, const Placement &pl = Placement())
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
            fail(HV_ERR_INVALID_ARG, path + ": no grid named '" + name + "' (the file has " +
                                         names() + ")");
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
    fail(HV_ERR_INVALID_ARG, path + ": grid '" + g.getName() +
                                 "' has no active voxels; pass an index box to read it");
}

CoordBBox read_box(const openvdb::GridBase &g, const std::string &path, const hv_vdb_read_opts *o)
{
    if (!o || !o->use_box)
        return default_box(g, path, true);
    for (int a = 0; a < 3; a++)
        if (o->box_hi[a] < o->box_lo[a]) {
            char buf[160];
            snprintf(buf, sizeof buf, ": index box is empty along %c (lo %d > hi %d)", "xyz"[a],
                     o->box_lo[a], o->box_hi[a]);
            fail(HV_ERR_INVALID_ARG, path + buf);
        }
    return CoordBBox(Coord(o->box_lo[0], o->box_lo[1], o->box_lo[2]),
                     Coord(o->box_hi[0], o->box_hi[1], o->box_hi[2]));
}

// A new dense grid for box with the geometry of g's transform.
hv_grid *new_dense(const openvdb::GridBase &g, const std::string &path, const CoordBBox &box)
{
    double h;
    Vec3d t0;
    require_uniform(g, path, &h, &t0);
    int n[3];
    for (int a = 0; a < 3; a++) {
        const int64_t len = (int64_t)box.max()[a] - (int64_t)box.min()[a] + 1;
        if (len <= 0 || len > std::numeric_limits<int>::max())
            fail(HV_ERR_INVALID_ARG, path + ": grid '" + g.getName() + "': index box too large");
        n[a] = (int)len;
    }
    double origin[3];
    for (int a = 0; a < 3; a++)
        origin[a] = t0[a] + ((double)box.min()[a] - 0.5) * h;
    hv_grid *out = nullptr;
    hv_status st = hv_grid_create(&out, 3, n, h, origin);
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

// A dense hv_grid block copied from a grid sampled at hv index (i,j,k).
template <class GridT, class Conv>
void copy_block(const GridT &grid, hv_grid *out, Conv &&conv)
{
    CoordBBox box(Coord(0, 0, 0), Coord(out->n[0] - 1, out->n[1] - 1, out->n[2] - 1));
    for_box(grid, box, [&](size_t idx, auto &acc, const Coord &c) {
        out->v[idx] = conv(acc.getValue(c), acc.isValueOn(c));
    });
}

// Trilinear sample of a cell-centred field at continuous index position p
// (sample (i,j,k) sits at p = (i,j,k)), clamped to the block.
float sample(const hv_grid *g, const Vec3d &p)
{
    int i0[3];
    double w[3];
    for (int a = 0; a < 3; a++) {
        double x = std::min(std::max(p[a], 0.0), (double)(g->n[a] - 1));
        int i = std::min((int)std::floor(x), std::max(g->n[a] - 2, 0));
        i0[a] = i;
        w[a] = g->n[a] > 1 ? x - i : 0.0;
    }
    double s = 0;
    for (int c = 0; c < 8; c++) {
        int ii = i0[0] + (c & 1), jj = i0[1] + ((c >> 1) & 1), kk = i0[2] + ((c >> 2) & 1);
        double wt = ((c & 1) ? w[0] : 1 - w[0]) * (((c >> 1) & 1) ? w[1] : 1 - w[1]) *
                    (((c >> 2) & 1) ? w[2] : 1 - w[2]);
        if (wt == 0)
            continue;
        s += wt * g->v[lin(g, std::min(ii, g->n[0] - 1), std::min(jj, g->n[1] - 1),
                           std::min(kk, g->n[2] - 1))];
    }
    return (float)s;
}

} // namespace

// ---- writer -------------------------------------------------------------------

struct hv_vdb_writer {
    openvdb::GridPtrVec grids;
    openvdb::MetaMap meta;
    bool has_index0 = false; // hv_vdb_writer_set_index_origin was called
    double index0[3] = {0, 0, 0};
};

namespace {

// Archive::write(stream, ...) is protected; File::write opens its own stream
// and never checks it after closing, so a full disk would go unnoticed.
class CheckedArchive : public openvdb::io::Archive {
  public:
    void write_to(std::ostream &os, const openvdb::GridCPtrVec &grids,
                  const openvdb::MetaMap &meta) const
    {
        this->write(os, grids, /*seekable=*/true, meta);
    }
};

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

// The placement of block g in this writer's index space: by default index
// (0,0,0) is the block's first voxel; after hv_vdb_writer_set_index_origin the
// transform puts index (0,0,0) at that world position and the block is shifted
// by whole voxels to keep its world position.
Placement placement(const hv_vdb_writer *w, const hv_grid *g, const char *name)
{
    Placement pl;
    if (!w->has_index0) {
        pl.xf = make_transform(g->h, g->origin);
        return pl;
    }
    for (int a = 0; a < 3; a++) {
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
        pl.off[a] = (int)r;
    }
    pl.xf = openvdb::math::Transform::createLinearTransform(g->h);
    pl.xf->postTranslate(Vec3d(w->index0[0], w->index0[1], w->index0[2]));
    return pl;
}

void finish_grid(hv_vdb_writer *w, openvdb::GridBase::Ptr grid, const hv_grid *g,
                 const char *name, const Placement &pl)
{
    grid->setName(name);
    grid->setSaveFloatAsHalf(false);
    grid->setCreator(std::string("heatvox ") + HV_VERSION_STRING);
    tag_block(*grid, g->n, pl.off);
    w->grids.push_back(grid);
}

} // namespace

extern "C" {

hv_status hv_vdb_writer_create(hv_vdb_writer **out)
{
    if (!out)
        return hv_error(HV_ERR_INVALID_ARG, "hv_vdb_writer_create: out is NULL");
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
                            acc.setValueOn(Coord(i + pl.off[0], j + pl.off[1], k + pl.off[2]), true);
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
            fail(HV_ERR_INVALID_ARG, "hv_vdb_writer_set_index_origin: writer and position are required");
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
        CheckedArchive ar;
        uint32_t comp = openvdb::io::COMPRESS_ACTIVE_MASK;
        comp |= openvdb::io::Archive::hasBloscCompression() ? openvdb::io::COMPRESS_BLOSC
                                                            : openvdb::io::COMPRESS_ZIP;
        ar.setCompression(comp);
        std::ofstream os(tmp, std::ios_base::out | std::ios_base::binary | std::ios_base::trunc);
        if (!os)
            fail(HV_ERR_IO, std::string(path) + ": cannot create the output file: " +
                                strerror(errno));
        openvdb::GridCPtrVec grids(w->grids.begin(), w->grids.end());
        ar.write_to(os, grids, w->meta);
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

// ---- reader -------------------------------------------------------------------

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
        return hv_error(HV_ERR_INVALID_ARG, "hv_vdb_read_float: out is NULL");
    *out = nullptr;
    return guarded(path ? path : "hv_vdb_read_float", [&] {
        OpenFile f(path);
        auto base = f.read(name);
        const CoordBBox box = read_box(*base, f.path, opts);
        GridOwner o;
        o.g = new_dense(*base, f.path, box);
        hv_grid *g = o.g;
        auto put = [g](size_t idx, auto &acc, const Coord &c) { g->v[idx] = (float)acc.getValue(c); };
        if (auto fg = openvdb::GridBase::grid<openvdb::FloatGrid>(base))
            for_box(*fg, box, put);
        else if (auto dg = openvdb::GridBase::grid<openvdb::DoubleGrid>(base))
            for_box(*dg, box, put);
        else
            fail(HV_ERR_INVALID_ARG, f.path + ": grid '" + name + "' holds " +
                                         base->valueType() + " values, not float or double");
        if (grid_class)
            *grid_class = (int)base->getGridClass();
        *out = o.release();
        return HV_OK;
    });
}

hv_status hv_vdb_read_vec3(const char *path, const char *name, const hv_vdb_read_opts *opts,
                           hv_grid **gx, hv_grid **gy, hv_grid **gz)
{
    if (!gx || !gy || !gz)
        return hv_error(HV_ERR_INVALID_ARG, "hv_vdb_read_vec3: an output pointer is NULL");
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
            fail(HV_ERR_INVALID_ARG, f.path + ": grid '" + name + "' holds " +
                                         base->valueType() + " values, not vec3s or vec3d");
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
        return hv_error(HV_ERR_INVALID_ARG, "hv_vdb_read_mask: out is NULL");
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
            fail(HV_ERR_INVALID_ARG, f.path + ": grid '" + name + "' holds " +
                                         base->valueType() +
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

// ---- reference tools ------------------------------------------------------------

hv_status hv_vdb_mesh_to_levelset(const double *verts, size_t nv, const uint32_t *tris, size_t nt,
                                  double band_voxels, hv_grid *out, double *seconds)
{
    return guarded("hv_vdb_mesh_to_levelset", [&] {
        init_vdb();
        check_grid(out, "hv_vdb_mesh_to_levelset: output grid");
        if (out->dim != 3)
            fail(HV_ERR_INVALID_ARG, "hv_vdb_mesh_to_levelset: output grid must be 3D");
        if (!verts || !tris || nv == 0 || nt == 0)
            fail(HV_ERR_INVALID_ARG, "hv_vdb_mesh_to_levelset: empty mesh");
        if (!(band_voxels >= 1) || !std::isfinite(band_voxels))
            fail(HV_ERR_INVALID_ARG, "hv_vdb_mesh_to_levelset: band must be at least 1 voxel");
        hv_status st = hv_check_finite_d(verts, 3 * nv, "mesh vertices");
        if (st)
            return st;
        std::vector<openvdb::Vec3s> pts(nv);
        for (size_t i = 0; i < nv; i++)
            pts[i] = openvdb::Vec3s((float)verts[3 * i], (float)verts[3 * i + 1],
                                    (float)verts[3 * i + 2]);
        std::vector<openvdb::Vec3I> tri(nt);
        for (size_t t = 0; t < nt; t++) {
            for (int c = 0; c < 3; c++)
                if (tris[3 * t + c] >= nv) {
                    char b[160];
                    snprintf(b, sizeof b,
                             "hv_vdb_mesh_to_levelset: triangle %zu uses vertex %u of %zu", t,
                             tris[3 * t + c], nv);
                    fail(HV_ERR_INVALID_ARG, b);
                }
            tri[t] = openvdb::Vec3I(tris[3 * t], tris[3 * t + 1], tris[3 * t + 2]);
        }
        auto xf = make_transform(out->h, out->origin);
        auto t0 = std::chrono::steady_clock::now();
        auto grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xf, pts, tri,
                                                                       (float)band_voxels);
        auto t1 = std::chrono::steady_clock::now();
        if (seconds)
            *seconds = std::chrono::duration<double>(t1 - t0).count();
        copy_block(*grid, out, [](float v, bool) { return v; });
        return HV_OK;
    });
}

} // extern "C"

namespace {

// Boundary values for sdfToExt: the field sampled at the index-space point
// OpenVDB hands over (see the header: we run in index space on purpose).
struct ScalarOp {
    const hv_grid *f;
    float operator()(const openvdb::Vec3R &p) const { return sample(f, p); }
};

struct VecOp {
    const hv_grid *fx, *fy, *fz;
    Vec3f operator()(const openvdb::Vec3R &p) const
    {
        return Vec3f(sample(fx, p), sample(fy, p), sample(fz, p));
    }
};

// phi/h on an identity transform: distances in voxels, and the callback's
// coordinates are our index coordinates whatever transform OpenVDB applies.
openvdb::FloatGrid::Ptr index_space_sdf(const hv_grid *phi, double band_voxels)
{
    hv_grid scaled = *phi;
    std::vector<float> v(hv_grid_count(phi));
    bool neg = false, pos = false;
    for (size_t i = 0; i < v.size(); i++) {
        v[i] = (float)(phi->v[i] / phi->h);
        neg |= v[i] < 0;
        pos |= v[i] > 0;
    }
    if (!neg || !pos)
        fail(HV_ERR_INVALID_ARG, "sdf_to_ext: phi has no zero crossing (all of one sign)");
    scaled.v = v.data();
    scaled.h = 1.0;
    const double o0[3] = {-0.5, -0.5, -0.5};
    for (int a = 0; a < 3; a++)
        scaled.origin[a] = o0[a];
    const bool dense = !(band_voxels > 0);
    double band = dense ? (double)std::max({phi->n[0], phi->n[1], phi->n[2]}) + 1.0 : band_voxels;
    auto grid = levelset_from(&scaled, band, dense, true);
    grid->tree().voxelizeActiveTiles(); // FastSweeping refuses active tiles
    return grid;
}

void check_ext_args(const hv_grid *phi, const hv_grid *const *in, const hv_grid *const *out,
                    int count)
{
    check_grid(phi, "sdf_to_ext: phi");
    for (int c = 0; c < count; c++) {
        check_grid(in[c], "sdf_to_ext: field");
        check_grid(out[c], "sdf_to_ext: output");
        check_same_shape(phi, in[c], "phi", "field");
        check_same_shape(phi, out[c], "phi", "output");
    }
    hv_status st = hv_check_finite(phi->v, hv_grid_count(phi), "phi");
    if (st)
        fail(st, hv_last_error());
}

} // namespace

extern "C" {

hv_status hv_vdb_sdf_to_ext(const hv_grid *phi, const hv_grid *field, double band_voxels,
                            int n_iter, float background, hv_grid *out, double *seconds)
{
    return guarded("hv_vdb_sdf_to_ext", [&] {
        init_vdb();
        const hv_grid *in[1] = {field};
        const hv_grid *outs[1] = {out};
        check_ext_args(phi, in, outs, 1);
        auto sdf = index_space_sdf(phi, band_voxels);
        auto t0 = std::chrono::steady_clock::now();
        auto ext = openvdb::tools::sdfToExt(*sdf, ScalarOp{field}, background, 0.0f,
                                            std::max(n_iter, 1));
        auto t1 = std::chrono::steady_clock::now();
        if (seconds)
            *seconds = std::chrono::duration<double>(t1 - t0).count();
        if (!ext)
            fail(HV_ERR_BACKEND, "hv_vdb_sdf_to_ext: OpenVDB returned no grid");
        copy_block(*ext, out, [background](float v, bool on) { return on ? v : background; });
        return HV_OK;
    });
}

hv_status hv_vdb_sdf_to_ext_vec3(const hv_grid *phi, const hv_grid *fx, const hv_grid *fy,
                                 const hv_grid *fz, double band_voxels, int n_iter,
                                 float background, hv_grid *ox, hv_grid *oy, hv_grid *oz,
                                 double *seconds)
{
    return guarded("hv_vdb_sdf_to_ext_vec3", [&] {
        init_vdb();
        const hv_grid *in[3] = {fx, fy, fz};
        const hv_grid *outs[3] = {ox, oy, oz};
        check_ext_args(phi, in, outs, 3);
        auto sdf = index_space_sdf(phi, band_voxels);
        auto t0 = std::chrono::steady_clock::now();
        auto ext = openvdb::tools::sdfToExt(*sdf, VecOp{fx, fy, fz},
                                            Vec3f(background, background, background), 0.0f,
                                            std::max(n_iter, 1));
        auto t1 = std::chrono::steady_clock::now();
        if (seconds)
            *seconds = std::chrono::duration<double>(t1 - t0).count();
        if (!ext)
            fail(HV_ERR_BACKEND, "hv_vdb_sdf_to_ext_vec3: OpenVDB returned no grid");
        CoordBBox box(Coord(0, 0, 0), Coord(ox->n[0] - 1, ox->n[1] - 1, ox->n[2] - 1));
        for_box(*ext, box, [&](size_t idx, auto &acc, const Coord &c) {
            const bool on = acc.isValueOn(c);
            const Vec3f v = acc.getValue(c);
            ox->v[idx] = on ? v[0] : background;
            oy->v[idx] = on ? v[1] : background;
            oz->v[idx] = on ? v[2] : background;
        });
        return HV_OK;
    });
}

} // extern "C"
