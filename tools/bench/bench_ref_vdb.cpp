// OpenVDB's own algorithms that heatvox is measured against (tools/bench/bench_ref.h):
// meshToLevelSet for heatvox sdf, sdfToExt (fast sweeping) for heatvox extend.
// Beside the benchmarks rather than in the library: heatvox's API does not
// offer them. Every entry point runs its body inside guarded(), which turns
// any exception into an hv_status and a message (ref_vdb_last_error()).
// Compiled like the library's OpenVDB shim (C++17, default visibility), from
// the public headers and OpenVDB's alone: the grids OpenVDB gets are built
// with OpenVDB's own API, as its users build them from dense arrays.
#include "bench_ref.h"

extern "C" {
#include "../cli.h"
}

#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/FastSweeping.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <mutex>
#include <new>
#include <string>
#include <vector>

namespace
{

using openvdb::Coord;
using openvdb::CoordBBox;
using openvdb::Vec3d;
using openvdb::Vec3f;

thread_local std::string last_error;

// An error detected here, carried to the C boundary.
struct Fail {
    hv_status st;
    std::string msg;
};

[[noreturn]] void fail(hv_status st, const std::string &msg) { throw Fail{st, msg}; }

hv_status record(hv_status st, const std::string &msg)
{
    last_error = msg;
    return st;
}

// `where` names the operation, so that OpenVDB's own messages still say which
// call failed.
template <class F> hv_status guarded(const char *where, F &&body)
{
    const std::string w(where);
    try {
        return body();
    } catch (const Fail &e) {
        return record(e.st, e.msg);
    } catch (const openvdb::IoError &e) {
        return record(HV_ERR_IO, w + ": " + e.what());
    } catch (const openvdb::Exception &e) {
        return record(HV_ERR_BACKEND, w + ": OpenVDB: " + e.what());
    } catch (const std::bad_alloc &) {
        return record(HV_ERR_NOMEM, w + ": out of memory");
    } catch (const std::exception &e) {
        return record(HV_ERR_BACKEND, w + ": " + e.what());
    } catch (...) {
        return record(HV_ERR_INTERNAL, w + ": unknown exception");
    }
}

void init_vdb()
{
    static std::once_flag init_flag;
    std::call_once(init_flag, [] { openvdb::initialize(); });
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

// A dense hv_grid block copied from a grid sampled at hv index (i,j,k).
template <class GridT, class Conv> void copy_block(const GridT &grid, hv_grid *out, Conv &&conv)
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
        ii = std::min(ii, g->n[0] - 1);
        jj = std::min(jj, g->n[1] - 1);
        kk = std::min(kk, g->n[2] - 1);
        s += wt * g->v[(size_t)ii + (size_t)g->n[0] * ((size_t)jj + (size_t)g->n[1] * (size_t)kk)];
    }
    return (float)s;
}

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

// phi/h as a level set on an identity transform: distances in voxels, and the
// callback's coordinates are our index coordinates whatever transform OpenVDB
// applies. Block voxel (i,j,k) is index (i,j,k); the voxels with |phi| under
// band_voxels are active (with band_voxels <= 0 all of the block's), the
// others hold -/+ the background by sign, and past the block the background.
// The grid the shim writes (hv_vdb_writer_add_levelset) for a surface inside
// the block; where the block cuts it, the shim carries phi's sign on to the end
// of the face's leaves (none of the level sets measured here is cut).
openvdb::FloatGrid::Ptr index_space_sdf(const hv_grid *phi, double band_voxels)
{
    std::vector<float> v(hv_grid_count(phi));
    bool neg = false, pos = false;
    for (size_t i = 0; i < v.size(); i++) {
        v[i] = (float)(phi->v[i] / phi->h);
        neg |= v[i] < 0;
        pos |= v[i] > 0;
    }
    if (!neg || !pos)
        fail(HV_ERR_INVALID_ARG, "sdf_to_ext: phi has no zero crossing (all of one sign)");
    const bool dense = !(band_voxels > 0);
    const float bg =
        (float)(dense ? (double)std::max({phi->n[0], phi->n[1], phi->n[2]}) + 1.0 : band_voxels);
    const CoordBBox block(Coord(0, 0, 0), Coord(phi->n[0] - 1, phi->n[1] - 1, phi->n[2] - 1));
    // x runs fastest in an hv_grid
    const openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ> values(block, v.data());
    auto grid = openvdb::FloatGrid::create(bg);
    openvdb::tools::copyFromDense(values, *grid, 0.0f); // voxels equal to bg come inactive
    if (dense) {
        auto all = openvdb::MaskGrid::create();
        all->fill(block, true, true);
        grid->topologyUnion(*all);
    } else {
        for (auto it = grid->beginValueOn(); it; ++it)
            if (!(std::fabs(*it) < bg)) {
                it.setValue(*it < 0 ? -bg : bg);
                it.setActiveState(false);
            }
    }
    openvdb::tools::prune(grid->tree());
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    grid->tree().voxelizeActiveTiles(); // FastSweeping refuses active tiles
    return grid;
}

// g, a grid the caller made like phi (hv_grid_create), with phi's voxels.
void check_like(const hv_grid *phi, const hv_grid *g, const char *what)
{
    if (!g || !g->v)
        fail(HV_ERR_INVALID_ARG, std::string("sdf_to_ext: ") + what + " is NULL");
    bool same = g->dim == phi->dim && g->h == phi->h;
    for (int a = 0; a < 3; a++)
        same = same && g->n[a] == phi->n[a] && g->origin[a] == phi->origin[a];
    if (!same)
        fail(HV_ERR_INVALID_ARG,
             std::string("sdf_to_ext: ") + what + " must have phi's size, voxel size and origin");
}

void check_ext_args(const hv_grid *phi, const hv_grid *const *in, const hv_grid *const *out,
                    int count)
{
    if (!phi || !phi->v)
        fail(HV_ERR_INVALID_ARG, "sdf_to_ext: phi is NULL");
    for (int c = 0; c < count; c++) {
        check_like(phi, in[c], "a field");
        check_like(phi, out[c], "an output");
    }
    hv_status st = hv_check_finite(phi->v, hv_grid_count(phi), "phi");
    if (st)
        fail(st, hv_last_error());
}

// The mesh as meshToLevelSet takes it: float points and index triples
// (indices checked; `where` names the caller in the error).
void vdb_mesh(const char *where, const double *verts, size_t nv, const uint32_t *tris, size_t nt,
              std::vector<openvdb::Vec3s> &pts, std::vector<openvdb::Vec3I> &tri)
{
    pts.resize(nv);
    for (size_t i = 0; i < nv; i++)
        pts[i] =
            openvdb::Vec3s((float)verts[3 * i], (float)verts[3 * i + 1], (float)verts[3 * i + 2]);
    tri.resize(nt);
    for (size_t t = 0; t < nt; t++) {
        for (int c = 0; c < 3; c++)
            if (tris[3 * t + c] >= nv) {
                char b[200];
                snprintf(b, sizeof b, "%s: triangle %zu uses vertex %u of %zu", where, t,
                         tris[3 * t + c], nv);
                fail(HV_ERR_INVALID_ARG, b);
            }
        tri[t] = openvdb::Vec3I(tris[3 * t], tris[3 * t + 1], tris[3 * t + 2]);
    }
}

// The boundary values of sdfToExt from a field grid, as a user writes them:
// trilinear (BoxSampler) at the index-space point the callback receives (see
// extend_off below). Copied per thread by sdfToExt, accessor and all.
template <class TreeT> struct SampleOp {
    openvdb::tree::ValueAccessor<const TreeT> acc;
    explicit SampleOp(const TreeT &tree) : acc(tree) {}
    typename TreeT::ValueType operator()(const openvdb::Vec3R &p) const
    {
        return openvdb::tools::BoxSampler::sample(acc, p);
    }
};

// sdfToExt of field off sdf (same index lattice), background 0, one iteration.
// OpenVDB 10.0.1 hands the callback index coordinates (it makes the extension
// grid with an identity transform, upstream issue #1640, open); a release that
// fixes it would hand world ones. The level set runs on an identity transform,
// so that they are index coordinates either way: sdfToExt uses only ratios of
// phi and the voxel size, so the extension is the same. The result gets the
// level set's transform back.
template <class FieldGridT>
typename FieldGridT::Ptr extend_off(openvdb::FloatGrid &sdf, const FieldGridT &field,
                                    double *seconds)
{
    using V = typename FieldGridT::ValueType;
    auto xf = sdf.transformPtr();
    sdf.setTransform(openvdb::math::Transform::createLinearTransform(1.0));
    typename FieldGridT::Ptr ext;
    try {
        auto t0 = std::chrono::steady_clock::now();
        ext = openvdb::tools::sdfToExt(sdf, SampleOp<typename FieldGridT::TreeType>(field.tree()),
                                       openvdb::zeroVal<V>(), 0.0f, 1);
        if (seconds)
            *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    } catch (...) {
        sdf.setTransform(xf);
        throw;
    }
    sdf.setTransform(xf);
    if (!ext)
        fail(HV_ERR_BACKEND, "sdfToExt returned no grid");
    ext->setTransform(xf->copy());
    return ext;
}

// A grid from tiles (hv_tiles' tiles are OpenVDB leaves: 8^3, at multiples of
// 8 in index space): one leaf per tile that has an active voxel in on (or
// every tile with all_tiles), value(tile, cell, active) at each voxel.
template <class GridT, class F>
void grid_from_tiles(GridT &grid, const hv_tiles *t, const uint64_t *on, bool all_tiles, F &&value)
{
    using LeafT = typename GridT::TreeType::LeafNodeType;
    static_assert(LeafT::DIM == HV_TILE, "hv_tiles are OpenVDB leaves");
    std::vector<std::unique_ptr<LeafT>> leaves(t->count);
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, t->count), [&](const tbb::blocked_range<size_t> &r) {
            for (size_t q = r.begin(); q != r.end(); q++) {
                bool any = all_tiles;
                for (int w = 0; w < HV_TILE && !any; w++)
                    any = on[q * HV_TILE + w] != 0;
                if (!any)
                    continue;
                const int32_t *o = t->ijk + 3 * q;
                auto leaf =
                    std::make_unique<LeafT>(Coord(o[0], o[1], o[2]), grid.background(), false);
                for (int c = 0; c < HV_TILE * HV_TILE * HV_TILE; c++) {
                    const bool act = on[q * HV_TILE + c / 64] >> (c % 64) & 1;
                    const openvdb::Index off =
                        LeafT::coordToOffset(Coord(o[0] + c % 8, o[1] + c / 8 % 8, o[2] + c / 64));
                    leaf->setValueOnly(off, value(q, c, act));
                    if (act)
                        leaf->setValueOn(off);
                }
                leaves[q] = std::move(leaf);
            }
        });
    auto &tree = grid.tree();
    for (auto &leaf : leaves)
        if (leaf)
            tree.addLeaf(leaf.release());
}

template <class FieldGridT, class Get>
void ext_tiles(const hv_tiles *phi, int ncomp, const hv_tiles *const in[3], hv_tiles *const out[3],
               double *seconds, Get &&get)
{
    using V = typename FieldGridT::ValueType;
    using LeafT = typename FieldGridT::TreeType::LeafNodeType;
    // The level set in voxels (identity transform, see extend_off): active
    // voxels hold phi/h, the others and the space between tiles the signed
    // background.
    const double h = phi->h;
    float bg = 1;
    const size_t cells = phi->count * HV_TILE * HV_TILE * HV_TILE;
    for (size_t i = 0; i < cells; i++)
        bg = std::max(bg, std::fabs(phi->v[i] / (float)h));
    auto sdf = openvdb::FloatGrid::create(bg);
    grid_from_tiles(*sdf, phi, phi->on, true, [&](size_t q, int c, bool act) {
        const float p = phi->v[q * 512 + c] / (float)h;
        return act ? p : std::copysign(bg, p);
    });
    openvdb::tools::signedFloodFill(sdf->tree());
    sdf->setGridClass(openvdb::GRID_LEVEL_SET);
    auto field = FieldGridT::create(openvdb::zeroVal<V>());
    grid_from_tiles(*field, in[0], in[0]->on, false, [&](size_t q, int c, bool) {
        V v = openvdb::zeroVal<V>();
        for (int k = 0; k < ncomp; k++)
            get(v, k) = in[k]->v[q * 512 + c];
        return v;
    });
    auto ext = extend_off(*sdf, *field, seconds);
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, phi->count), [&](const tbb::blocked_range<size_t> &r) {
            for (size_t q = r.begin(); q != r.end(); q++) {
                const int32_t *o = phi->ijk + 3 * q;
                const auto *leaf = ext->tree().probeConstLeaf(Coord(o[0], o[1], o[2]));
                for (int k = 0; k < ncomp; k++)
                    for (int w = 0; w < HV_TILE; w++)
                        out[k]->on[q * HV_TILE + w] = 0;
                for (int c = 0; leaf && c < 512; c++) {
                    const openvdb::Index off =
                        LeafT::coordToOffset(Coord(o[0] + c % 8, o[1] + c / 8 % 8, o[2] + c / 64));
                    if (!leaf->isValueOn(off))
                        continue;
                    V v = leaf->getValue(off);
                    for (int k = 0; k < ncomp; k++) {
                        out[k]->v[q * 512 + c] = get(v, k);
                        out[k]->on[q * HV_TILE + c / 64] |= 1ull << (c % 64);
                    }
                }
            }
        });
    for (int k = 0; k < ncomp; k++) {
        size_t n = 0;
        for (size_t w = 0; w < HV_TILE * phi->count; w++)
            n += (size_t)__builtin_popcountll(out[k]->on[w]);
        out[k]->active = n;
    }
}

void check_tiles(const hv_tiles *t, const hv_tiles *phi, const char *what)
{
    if (!t || (t->count && (!t->ijk || !t->v || !t->on)))
        fail(HV_ERR_INVALID_ARG, std::string("ref_vdb_sdf_to_ext_tiles: ") + what + " is NULL");
    if (phi && (t->count != phi->count ||
                (t->count && memcmp(t->ijk, phi->ijk, 3 * t->count * sizeof *t->ijk))))
        fail(HV_ERR_INVALID_ARG,
             std::string("ref_vdb_sdf_to_ext_tiles: ") + what + " must have phi's tiles");
}

} // namespace

extern "C" {

hv_status ref_vdb_ext_file(const char *in_path, const char *ls_name, const char *field_name,
                           const char *out_path)
{
    return guarded("ref_vdb_ext_file", [&] {
        init_vdb();
        openvdb::io::File file(in_path);
        file.open();
        for (const char *name : {ls_name, field_name})
            if (!file.hasGrid(name))
                fail(HV_ERR_INVALID_ARG,
                     std::string(in_path) + ": no grid '" + name + "' in the file");
        auto sdf = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(ls_name));
        auto field = file.readGrid(field_name);
        file.close();
        if (!sdf)
            fail(HV_ERR_INVALID_ARG,
                 std::string(in_path) + ": grid '" + ls_name + "' is not a float grid");
        if (field->transform() != sdf->transform())
            fail(HV_ERR_INVALID_ARG, std::string(in_path) + ": grids '" + ls_name + "' and '" +
                                         field_name + "' have different transforms");
        if (sdf->tree().hasActiveTiles())
            sdf->tree().voxelizeActiveTiles(); // FastSweeping refuses active tiles
        openvdb::GridBase::Ptr ext;
        if (auto v = openvdb::gridPtrCast<openvdb::Vec3SGrid>(field))
            ext = extend_off(*sdf, *v, nullptr);
        else if (auto f = openvdb::gridPtrCast<openvdb::FloatGrid>(field))
            ext = extend_off(*sdf, *f, nullptr);
        else
            fail(HV_ERR_INVALID_ARG, std::string(in_path) + ": grid '" + field_name + "' is " +
                                         field->valueType() + ", not float or vec3s");
        ext->setName(field_name);
        ext->setVectorType(field->getVectorType());
        field.reset();
        openvdb::io::File out(out_path);
        out.write({sdf, ext});
        out.close();
        return HV_OK;
    });
}

hv_status ref_vdb_sdf_to_ext_tiles(const hv_tiles *phi, int ncomp, const hv_tiles *const in[3],
                                   hv_tiles *const out[3], double *seconds)
{
    return guarded("ref_vdb_sdf_to_ext_tiles", [&] {
        init_vdb();
        if (ncomp != 1 && ncomp != 3)
            fail(HV_ERR_INVALID_ARG, "ref_vdb_sdf_to_ext_tiles: ncomp must be 1 or 3");
        check_tiles(phi, nullptr, "phi");
        if (!(phi->h > 0))
            fail(HV_ERR_INVALID_ARG, "ref_vdb_sdf_to_ext_tiles: phi's voxel size must be positive");
        for (int k = 0; k < ncomp; k++) {
            check_tiles(in[k], phi, "a field");
            check_tiles(out[k], phi, "an output");
        }
        if (ncomp == 3)
            ext_tiles<openvdb::Vec3SGrid>(
                phi, 3, in, out, seconds, [](auto &v, int k) -> auto & { return v[k]; });
        else
            ext_tiles<openvdb::FloatGrid>(
                phi, 1, in, out, seconds, [](auto &v, int) -> auto & { return v; });
        return HV_OK;
    });
}

hv_status ref_vdb_mesh_to_levelset(const double *verts, size_t nv, const uint32_t *tris, size_t nt,
                                   double band_voxels, hv_grid *out, double *seconds)
{
    return guarded("ref_vdb_mesh_to_levelset", [&] {
        init_vdb();
        if (!out || !out->v || out->dim != 3)
            fail(HV_ERR_INVALID_ARG, "ref_vdb_mesh_to_levelset: the output grid must be 3D");
        if (!verts || !tris || nv == 0 || nt == 0)
            fail(HV_ERR_INVALID_ARG, "ref_vdb_mesh_to_levelset: empty mesh");
        if (!(band_voxels >= 1) || !std::isfinite(band_voxels))
            fail(HV_ERR_INVALID_ARG, "ref_vdb_mesh_to_levelset: band must be at least 1 voxel");
        hv_status st = hv_check_finite_d(verts, 3 * nv, "mesh vertices");
        if (st)
            fail(st, hv_last_error());
        std::vector<openvdb::Vec3s> pts;
        std::vector<openvdb::Vec3I> tri;
        vdb_mesh("ref_vdb_mesh_to_levelset", verts, nv, tris, nt, pts, tri);
        // index (i,j,k) at the cell centre origin + (i+1/2)h (heatvox/vdb.h)
        auto xf = openvdb::math::Transform::createLinearTransform(out->h);
        xf->postTranslate(Vec3d(out->origin[0] + 0.5 * out->h, out->origin[1] + 0.5 * out->h,
                                out->origin[2] + 0.5 * out->h));
        auto t0 = std::chrono::steady_clock::now();
        auto grid =
            openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xf, pts, tri, (float)band_voxels);
        auto t1 = std::chrono::steady_clock::now();
        if (seconds)
            *seconds = std::chrono::duration<double>(t1 - t0).count();
        copy_block(*grid, out, [](float v, bool) { return v; });
        return HV_OK;
    });
}

hv_status ref_vdb_mesh_to_vdb_file(const double *verts, size_t nv, const uint32_t *tris, size_t nt,
                                   double h, const double index0_world[3], double band_voxels,
                                   const char *path)
{
    return guarded("ref_vdb_mesh_to_vdb_file", [&] {
        init_vdb();
        if (!verts || !tris || nv == 0 || nt == 0)
            fail(HV_ERR_INVALID_ARG, "ref_vdb_mesh_to_vdb_file: empty mesh");
        if (!(h > 0) || !(band_voxels >= 1) || !std::isfinite(band_voxels))
            fail(HV_ERR_INVALID_ARG, "ref_vdb_mesh_to_vdb_file: bad voxel size or band");
        std::vector<openvdb::Vec3s> pts;
        std::vector<openvdb::Vec3I> tri;
        vdb_mesh("ref_vdb_mesh_to_vdb_file", verts, nv, tris, nt, pts, tri);
        auto xf = openvdb::math::Transform::createLinearTransform(h);
        xf->postTranslate(openvdb::Vec3d(index0_world[0], index0_world[1], index0_world[2]));
        auto grid =
            openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xf, pts, tri, (float)band_voxels);
        pts = std::vector<openvdb::Vec3s>();
        tri = std::vector<openvdb::Vec3I>();
        grid->setName("sdf");
        grid->setSaveFloatAsHalf(false);
        openvdb::io::File file(path);
        file.write({grid});
        file.close();
        return HV_OK;
    });
}

hv_status ref_vdb_sdf_to_ext(const hv_grid *phi, const hv_grid *field, double band_voxels,
                             int n_iter, float background, hv_grid *out, double *seconds)
{
    return guarded("ref_vdb_sdf_to_ext", [&] {
        init_vdb();
        const hv_grid *in[1] = {field};
        const hv_grid *outs[1] = {out};
        check_ext_args(phi, in, outs, 1);
        auto sdf = index_space_sdf(phi, band_voxels);
        auto t0 = std::chrono::steady_clock::now();
        auto ext =
            openvdb::tools::sdfToExt(*sdf, ScalarOp{field}, background, 0.0f, std::max(n_iter, 1));
        auto t1 = std::chrono::steady_clock::now();
        if (seconds)
            *seconds = std::chrono::duration<double>(t1 - t0).count();
        if (!ext)
            fail(HV_ERR_BACKEND, "ref_vdb_sdf_to_ext: OpenVDB returned no grid");
        copy_block(*ext, out, [background](float v, bool on) { return on ? v : background; });
        return HV_OK;
    });
}

hv_status ref_vdb_sdf_to_ext_vec3(const hv_grid *phi, const hv_grid *fx, const hv_grid *fy,
                                  const hv_grid *fz, double band_voxels, int n_iter,
                                  float background, hv_grid *ox, hv_grid *oy, hv_grid *oz,
                                  double *seconds)
{
    return guarded("ref_vdb_sdf_to_ext_vec3", [&] {
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
            fail(HV_ERR_BACKEND, "ref_vdb_sdf_to_ext_vec3: OpenVDB returned no grid");
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

const char *ref_vdb_last_error(void) { return last_error.c_str(); }

int ref_vdb_fail(const char *cmd, const char *what, hv_status st)
{
    const char *detail = ref_vdb_last_error();
    fprintf(stderr, "heatvox %s: %s: %s%s%s\n", cmd, what, hv_status_str(st), *detail ? ": " : "",
            detail);
    return HV_EXIT_FAIL;
}

} // extern "C"
