// The OpenVDB reader behind include/heatvox/vdb.h: lists the grids of a file,
// reads float, vec3 and mask grids onto dense heatvox grids, index boxes and
// metadata. Files are checked against their size (vdb_check.h) before OpenVDB
// reads them.
#include "heatvox/vdb.h"
#include "io/vdb_internal.h"
#include "io/vdb_check.h"

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <string>

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
