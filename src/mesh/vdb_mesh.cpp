// Isosurface extraction behind include/heatvox/vdb.h (hv_grid_to_mesh):
// OpenVDB's tools::VolumeToMesh (dual contouring with Nielson's edge groups,
// optionally merging flat regions) on a FloatGrid built from the dense block,
// its quads split into triangles, and the result checked to be a closed,
// manifold, consistently oriented surface before it is handed out.
//
// Closure at the walls. VolumeToMesh looks only at edges between two samples
// of which one is active, and reads leaves, tiles or the background for the
// other; a block copied as it is would leave the surface open where the inside
// reaches a wall (the background beyond it is never compared). So the block is
// copied with a ring of one voxel around it, every voxel of block and ring
// active: a ring voxel across a face from an inside sample v gets the mirrored
// value 2·iso − v (outside), putting the crossing exactly on the block's wall,
// half a voxel beyond the last sample; every other ring voxel and the
// background beyond are outside. Cells outside the block therefore count as
// outside, the surface is capped on the walls, and the enclosed volume is the
// inside cells' (within the interpolation of the zero set).
//
// Geometry. The mesher's points (averages of edge crossings) are moved onto
// the zero set of the trilinear interpolant; with adaptivity, merged regions
// whose triangles stray from it by more than adaptivity/2 voxels are split
// again (the adaptivity mask) and the volume meshed anew. Topology is never
// edited: the mesher's edge groups make it closed and manifold, and that is
// checked, not assumed (an adaptive mesh with a defect is meshed again with
// its regions kept apart, the uniform mesh being the last resort).
#include "heatvox/vdb.h"
#include "io/vdb_internal.h"
#include "vdb_volmesh.h"

extern "C" {
#include "mesh_internal.h"
}

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

using namespace hv_vdb_shim;

namespace
{

using openvdb::Coord;

inline size_t lin(const hv_grid *g, int i, int j, int k)
{
    return (size_t)i + (size_t)g->n[0] * ((size_t)j + (size_t)g->n[1] * (size_t)k);
}

int floor_div(int a, int d) { return a >= 0 ? a / d : -((-a + d - 1) / d); }

// The block [0,n) and its ring [-1,n] as leaves, in index space (identity
// transform: sample (i,j,k) at index (i,j,k)), every voxel of block and ring
// active. Voxels of the leaves beyond the ring are inactive and outside; so is
// the background. A leaf whose neighbourhood (the 3^3 leaves around it) lies
// on one side of the isovalue becomes an inactive tile of that side: no edge
// the mesher compares, no corner of a crossed voxel, no point it or the
// projection samples (all within 2 voxels of a crossing) falls in it.
openvdb::FloatGrid::Ptr padded_grid(const hv_grid *g, float iso, float outside)
{
    using LeafT = openvdb::FloatGrid::TreeType::LeafNodeType;
    const int D = (int)LeafT::DIM;
    const int *n = g->n;
    int l0[3];
    size_t L[3];
    for (int a = 0; a < 3; a++) {
        l0[a] = floor_div(-1, D);
        L[a] = (size_t)(floor_div(n[a], D) - l0[a] + 1);
    }
    const size_t nleaf = L[0] * L[1] * L[2];
    auto leaf_origin = [&](size_t l) {
        return Coord((l0[0] + (int)(l % L[0])) * D, (l0[1] + (int)(l / L[0] % L[1])) * D,
                     (l0[2] + (int)(l / L[0] / L[1])) * D);
    };
    // A ring voxel across a face from block sample v: the crossing of the
    // edge between them lies on the wall when v is inside, none otherwise.
    auto mirror = [&](float v) -> float {
        if (!(v < iso))
            return outside;
        return (float)std::min(2.0 * (double)iso - (double)v, (double)FLT_MAX);
    };
    // The value of voxel (x,y,z); false beyond the ring.
    auto voxel = [&](int x, int y, int z, float *v) {
        const int c[3] = {x, y, z};
        int out_axis = -1, nout = 0;
        for (int a = 0; a < 3; a++)
            if (c[a] < 0 || c[a] >= n[a]) {
                if (c[a] < -1 || c[a] > n[a])
                    return false;
                nout++;
                out_axis = a;
            }
        if (nout == 0) {
            *v = g->v[lin(g, x, y, z)];
        } else if (nout == 1) {
            int b[3] = {x, y, z};
            b[out_axis] = c[out_axis] < 0 ? 0 : n[out_axis] - 1;
            *v = mirror(g->v[lin(g, b[0], b[1], b[2])]);
        } else {
            *v = outside;
        }
        return true;
    };
    // Which sides each leaf holds: 1 inside, 2 outside.
    std::vector<uint8_t> sides(nleaf, 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nleaf),
                      [&](const tbb::blocked_range<size_t> &r) {
                          for (size_t l = r.begin(); l != r.end(); l++) {
                              const Coord o = leaf_origin(l);
                              uint8_t s = 0;
                              for (int x = o[0]; x < o[0] + D && s != 3; x++)
                                  for (int y = o[1]; y < o[1] + D; y++)
                                      for (int z = o[2]; z < o[2] + D; z++) {
                                          float v = outside;
                                          voxel(x, y, z, &v);
                                          s |= v < iso ? 1 : 2;
                                      }
                              sides[l] = s;
                          }
                      });
    auto near_sides = [&](size_t l) {
        const long c[3] = {(long)(l % L[0]), (long)(l / L[0] % L[1]), (long)(l / L[0] / L[1])};
        uint8_t s = 0;
        for (long dz = -1; dz <= 1; dz++)
            for (long dy = -1; dy <= 1; dy++)
                for (long dx = -1; dx <= 1; dx++) {
                    const long x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
                    if (x < 0 || y < 0 || z < 0 || x >= (long)L[0] || y >= (long)L[1] ||
                        z >= (long)L[2])
                        s |= 2; // beyond the leaves: the background, outside
                    else
                        s |= sides[(size_t)x + L[0] * ((size_t)y + L[1] * (size_t)z)];
                }
        return s;
    };
    std::vector<std::unique_ptr<LeafT>> leaves(nleaf);
    std::vector<uint8_t> tile(nleaf, 0);
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, nleaf), [&](const tbb::blocked_range<size_t> &r) {
            for (size_t l = r.begin(); l != r.end(); l++) {
                const uint8_t s = near_sides(l);
                if (s != 3) {
                    tile[l] = s;
                    continue;
                }
                const Coord o = leaf_origin(l);
                auto leaf = std::make_unique<LeafT>(o, outside, false);
                for (int x = o[0]; x < o[0] + D; x++)
                    for (int y = o[1]; y < o[1] + D; y++)
                        for (int z = o[2]; z < o[2] + D; z++) {
                            float v;
                            if (voxel(x, y, z, &v))
                                leaf->setValueOn(LeafT::coordToOffset(Coord(x, y, z)), v);
                        }
                leaves[l] = std::move(leaf);
            }
        });
    const float inside = std::min(iso - std::fabs(outside - iso), std::nextafter(iso, -FLT_MAX));
    auto grid = openvdb::FloatGrid::create(outside);
    for (size_t l = 0; l < nleaf; l++) {
        if (leaves[l])
            grid->tree().addLeaf(leaves[l].release());
        else if (tile[l] == 1)
            grid->tree().addTile(1, leaf_origin(l), inside, false);
    }
    grid->setGridClass(openvdb::GRID_LEVEL_SET); // inside = below iso, no inverted orientation
    return grid;
}

struct Tri {
    uint32_t v[3];
};

// Counts edges used once, more than twice, or twice in the same direction.
struct EdgeDefects {
    size_t boundary = 0, nonmanifold = 0, inconsistent = 0;
    std::vector<uint32_t> bad_vertices; // endpoints of the defective edges
    size_t total() const { return boundary + nonmanifold + inconsistent; }
};

EdgeDefects edge_defects(const std::vector<Tri> &tris)
{
    // key: the undirected edge (lo << 32 | hi) shifted left by one, with the
    // direction (a < b) in the low bit
    std::vector<std::pair<uint64_t, uint8_t>> e;
    e.reserve(3 * tris.size());
    for (const Tri &t : tris)
        for (int k = 0; k < 3; k++) {
            uint32_t a = t.v[k], b = t.v[(k + 1) % 3];
            uint64_t lo = std::min(a, b), hi = std::max(a, b);
            e.emplace_back(lo << 32 | hi, (uint8_t)(a < b));
        }
    std::sort(e.begin(), e.end());
    EdgeDefects d;
    for (size_t i = 0; i < e.size();) {
        size_t j = i;
        while (j < e.size() && e[j].first == e[i].first)
            j++;
        bool bad = false;
        if (j - i == 1) {
            d.boundary++;
            bad = true;
        } else if (j - i > 2) {
            d.nonmanifold++;
            bad = true;
        } else if (e[i].second == e[i + 1].second) {
            d.inconsistent++;
            bad = true;
        }
        if (bad) {
            d.bad_vertices.push_back((uint32_t)(e[i].first >> 32));
            d.bad_vertices.push_back((uint32_t)(e[i].first & 0xffffffffu));
        }
        i = j;
    }
    return d;
}

inline double dist2(const openvdb::Vec3s &a, const openvdb::Vec3s &b)
{
    double s = 0;
    for (int k = 0; k < 3; k++)
        s += ((double)a[k] - b[k]) * ((double)a[k] - b[k]);
    return s;
}

// One run of VolumeToMesh: points (index space) and triangles, turned
// outward (OpenVDB orders a level set's quads clockwise seen from outside).
// Quads are split along their shorter diagonal (the flatter pair of triangles,
// no sliver across a long one), both halves keeping the quad's orientation.
// Polygons repeating a vertex (merged regions meeting in adaptive meshing) lose
// their zero-length edges; what remains with fewer than three distinct corners
// is dropped: it covers no area and traverses each of its edges both ways, so
// dropping it changes no other edge's use count or direction balance.
void run_mesher(const openvdb::FloatGrid &grid, float iso, double adaptivity,
                const openvdb::BoolTree::Ptr &keep, std::vector<openvdb::Vec3s> &points,
                std::vector<Tri> &tris)
{
    std::vector<openvdb::Vec4I> quads;
    std::vector<openvdb::Vec3I> triangles;
    volume_to_mesh(grid, iso, adaptivity, keep, points, quads, triangles);
    tris.clear();
    auto add = [&](uint32_t a, uint32_t b, uint32_t c) {
        if (a != b && b != c && a != c)
            tris.push_back(Tri{{a, c, b}});
    };
    for (const openvdb::Vec4I &q : quads) {
        if (dist2(points[q[0]], points[q[2]]) <= dist2(points[q[1]], points[q[3]])) {
            add(q[0], q[1], q[2]);
            add(q[0], q[2], q[3]);
        } else {
            add(q[0], q[1], q[3]);
            add(q[1], q[2], q[3]);
        }
    }
    for (const openvdb::Vec3I &t : triangles)
        add(t[0], t[1], t[2]);
}

// How far a triangle strays from the isosurface: the largest |phi - iso| of the
// trilinear field at its corners and on a barycentric lattice of step at most
// one voxel over it (phi a distance field, so that |phi - iso| is the distance
// to the isosurface to first order, in world units).
// Also gives the index point where that largest value was found, and with
// `over`, every point farther than `limit`.
double stray(const openvdb::tree::ValueAccessor<const openvdb::FloatTree> &acc, float iso,
             const openvdb::Vec3s *p[3], openvdb::Vec3d &worst, double limit = 0,
             std::vector<openvdb::Vec3d> *over = nullptr)
{
    double L = std::sqrt(std::max({dist2(*p[0], *p[1]), dist2(*p[1], *p[2]), dist2(*p[2], *p[0])}));
    int m = std::max(1, (int)std::ceil(L));
    double best = -1;
    for (int i = 0; i <= m; i++)
        for (int j = 0; i + j <= m; j++) {
            double a = (double)i / m, b = (double)j / m, c = 1 - a - b;
            openvdb::Vec3d x =
                a * openvdb::Vec3d(*p[0]) + b * openvdb::Vec3d(*p[1]) + c * openvdb::Vec3d(*p[2]);
            double e = std::fabs((double)openvdb::tools::BoxSampler::sample(acc, x) - iso);
            if (over && e > limit)
                over->push_back(x);
            if (e > best) {
                best = e;
                worst = x;
            }
        }
    return best;
}

// Most meshing passes that split merged regions again.
constexpr int MAX_PASSES = 8;

// Marks the voxel (cell between samples) holding index point x in the mask of
// regions that may not merge; true when it was not marked yet.
bool keep_voxel(openvdb::BoolTree &keep, const openvdb::Vec3d &x)
{
    const Coord c((int)std::floor(x[0]), (int)std::floor(x[1]), (int)std::floor(x[2]));
    if (keep.isValueOn(c))
        return false;
    keep.setValueOn(c, true);
    return true;
}

// Moves each point onto the zero set of the trilinear field by Newton steps
// along its gradient (at most two, each taken only when it brings |phi - iso|
// down, the whole move at most half a voxel). The mesher's points are
// averages of edge crossings, which sit inside convex parts and outside
// concave ones by about the curvature times h^2: a mesh that encloses less
// than the grid's inside. Works in index space (voxel units).
void project_points(const openvdb::FloatGrid &grid, float iso, std::vector<openvdb::Vec3s> &points)
{
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, points.size()), [&](const tbb::blocked_range<size_t> &r) {
            openvdb::tree::ValueAccessor<const openvdb::FloatTree> acc(grid.tree());
            auto eval = [&](const openvdb::Vec3d &x, openvdb::Vec3d *grad) {
                const Coord c((int)std::floor(x[0]), (int)std::floor(x[1]), (int)std::floor(x[2]));
                const double f[3] = {x[0] - c[0], x[1] - c[1], x[2] - c[2]};
                double v[2][2][2];
                for (int i = 0; i < 2; i++)
                    for (int j = 0; j < 2; j++)
                        for (int k = 0; k < 2; k++)
                            v[i][j][k] = (double)acc.getValue(c.offsetBy(i, j, k)) - iso;
                double val = 0;
                openvdb::Vec3d g(0, 0, 0);
                for (int i = 0; i < 2; i++)
                    for (int j = 0; j < 2; j++)
                        for (int k = 0; k < 2; k++) {
                            const double wx = i ? f[0] : 1 - f[0], wy = j ? f[1] : 1 - f[1],
                                         wz = k ? f[2] : 1 - f[2];
                            val += wx * wy * wz * v[i][j][k];
                            g[0] += (i ? 1 : -1) * wy * wz * v[i][j][k];
                            g[1] += (j ? 1 : -1) * wx * wz * v[i][j][k];
                            g[2] += (k ? 1 : -1) * wx * wy * v[i][j][k];
                        }
                *grad = g;
                return val;
            };
            for (size_t i = r.begin(); i != r.end(); i++) {
                const openvdb::Vec3d p0(points[i]);
                openvdb::Vec3d p = p0, g;
                double e = eval(p, &g);
                for (int it = 0; it < 2 && e != 0; it++) {
                    const double g2 = g.lengthSqr();
                    if (!(g2 > 0))
                        break;
                    openvdb::Vec3d q = p - (e / g2) * g;
                    if ((q - p0).length() > 0.5)
                        break;
                    openvdb::Vec3d gq;
                    const double eq = eval(q, &gq);
                    if (!(std::fabs(eq) < std::fabs(e)))
                        break;
                    p = q;
                    e = eq;
                    g = gq;
                }
                points[i] = openvdb::Vec3s((float)p[0], (float)p[1], (float)p[2]);
            }
        });
}

// Moves apart vertices that share a position in float (the precision of STL,
// and so also in double): where samples equal the isovalue exactly, the
// crossings of several voxels fall on one sample and their points coincide.
// The topology is the mesher's and stays; readers that weld by position would
// merge such vertices and break it. In a group of m coincident vertices, the
// k-th (k = 1..m-1; the first stays) moves towards the centroid of its
// neighbours by min(k·step, k/m · a quarter of the way), so that no two land on
// the same point and each stays inside its star; step starts at 1e-4 voxel and
// doubles while coincidences remain. The topology is left as it is: a surface
// that the data pinch to a point stays a surface, now a tiny one.
void separate_coincident(std::vector<double> &v, const std::vector<uint32_t> &idx, double h)
{
    const size_t nv = v.size() / 3;
    auto key = [&](size_t i) {
        return std::array<float, 3>{(float)v[3 * i], (float)v[3 * i + 1], (float)v[3 * i + 2]};
    };
    std::vector<uint32_t> order(nv);
    for (size_t i = 0; i < nv; i++)
        order[i] = (uint32_t)i;
    std::vector<int64_t> slot(nv, -1);
    double step = 1e-4 * h;
    for (int round = 0; round < 40; round++, step *= 2) {
        std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
            auto ka = key(a), kb = key(b);
            return ka != kb ? ka < kb : a < b;
        });
        struct Move {
            uint32_t vertex;
            double rank, group;
        };
        std::vector<Move> moves;
        for (size_t i = 0; i < nv;) {
            size_t j = i + 1;
            while (j < nv && key(order[j]) == key(order[i]))
                j++;
            for (size_t r = i + 1; r < j; r++)
                moves.push_back(Move{order[r], (double)(r - i), (double)(j - i)});
            i = j;
        }
        if (moves.empty())
            return;
        for (size_t k = 0; k < moves.size(); k++)
            slot[moves[k].vertex] = (int64_t)k;
        std::vector<double> sum(4 * moves.size(), 0.0); // neighbours' positions and count
        for (size_t t = 0; t < idx.size(); t += 3)
            for (int c = 0; c < 3; c++) {
                int64_t k = slot[idx[t + c]];
                if (k < 0)
                    continue;
                for (int o = 1; o < 3; o++) {
                    uint32_t b = idx[t + (c + o) % 3];
                    for (int a = 0; a < 3; a++)
                        sum[4 * k + a] += v[3 * b + a];
                    sum[4 * k + 3] += 1;
                }
            }
        for (size_t k = 0; k < moves.size(); k++) {
            const Move &mv = moves[k];
            double *p = &v[3 * mv.vertex], dir[3], len = 0;
            for (int a = 0; a < 3; a++) {
                dir[a] = sum[4 * k + 3] > 0 ? sum[4 * k + a] / sum[4 * k + 3] - p[a] : 0;
                len += dir[a] * dir[a];
            }
            len = std::sqrt(len);
            double s = mv.rank * step;
            if (len > 1e-9 * h) {
                s = std::min(s, 0.25 * len * mv.rank / mv.group);
            } else {
                // Its neighbours coincide with it too: a closed bubble of
                // points on one sample (an outside sample at the isovalue
                // with inside neighbours). Octant diagonals by rank.
                const size_t o = (size_t)mv.rank % 8;
                dir[0] = o & 1 ? 1 : -1;
                dir[1] = o & 2 ? 1 : -1;
                dir[2] = o & 4 ? 1 : -1;
                len = std::sqrt(3.0);
            }
            for (int a = 0; a < 3; a++)
                p[a] += s * dir[a] / len;
            slot[mv.vertex] = -1;
        }
    }
}

} // namespace

extern "C" {

hv_status hv_grid_to_mesh(const hv_grid *g, double isovalue, double adaptivity, hv_mesh **out)
{
    if (!out)
        return hv__error(HV_ERR_INVALID_ARG, "hv_grid_to_mesh: out is NULL");
    *out = nullptr;
    return guarded("hv_grid_to_mesh", [&] {
        if (!g || !g->v)
            fail(HV_ERR_INVALID_ARG, "hv_grid_to_mesh: grid is NULL");
        if (g->dim != 3)
            fail(HV_ERR_INVALID_ARG,
                 "hv_grid_to_mesh: the grid must be 3D (dim " + std::to_string(g->dim) + ")");
        hv_status st = hv_check_dims(3, g->n, g->h, 0);
        if (st)
            return st;
        if (!(adaptivity >= 0 && adaptivity <= 1))
            fail(HV_ERR_INVALID_ARG, "hv_grid_to_mesh: adaptivity must be in [0, 1], got " +
                                         std::to_string(adaptivity));
        if (!std::isfinite(isovalue) || std::fabs(isovalue) > 1e30)
            fail(HV_ERR_INVALID_ARG, "hv_grid_to_mesh: isovalue must be finite (within 1e30)");
        const size_t count = hv_grid_count(g);
        if ((st = hv_check_finite(g->v, count, "hv_grid_to_mesh: grid")))
            return st;
        const float iso = (float)isovalue;
        size_t inside = 0;
        for (size_t i = 0; i < count; i++)
            inside += g->v[i] < iso;
        if (!inside)
            fail(HV_ERR_INVALID_ARG, "hv_grid_to_mesh: no value below the isovalue " +
                                         std::to_string(isovalue) + ": there is no surface");
        init_vdb();
        const float outside = std::max(iso + (float)g->h, std::nextafter(iso, FLT_MAX));
        auto grid = padded_grid(g, iso, outside);

        // Adaptive meshing merges regions of 2^3 up to 8^3 voxels whose
        // normals differ by 1 - cos <= adaptivity. Regions with a triangle
        // that strays more than adaptivity/2 voxels from the isosurface, or
        // that touches a defective edge, are kept from merging (the
        // adaptivity mask) and the volume meshed again, until none is left
        // (or MAX_PASSES).
        const double max_stray = 0.5 * adaptivity * g->h;
        std::vector<openvdb::Vec3s> points;
        std::vector<Tri> tris;
        openvdb::BoolTree::Ptr keep;
        EdgeDefects d;
        for (int pass = 0;; pass++) {
            run_mesher(*grid, iso, adaptivity, keep, points, tris);
            project_points(*grid, iso, points);
            d = edge_defects(tris);
            if (adaptivity == 0 || pass == MAX_PASSES)
                break;
            std::vector<uint8_t> bad(tris.size(), 0);
            {
                const openvdb::FloatTree &tree = grid->tree();
                tbb::parallel_for(tbb::blocked_range<size_t>(0, tris.size()),
                                  [&](const tbb::blocked_range<size_t> &r) {
                                      openvdb::tree::ValueAccessor<const openvdb::FloatTree> acc(
                                          tree);
                                      for (size_t t = r.begin(); t != r.end(); t++) {
                                          const openvdb::Vec3s *p[3] = {&points[tris[t].v[0]],
                                                                        &points[tris[t].v[1]],
                                                                        &points[tris[t].v[2]]};
                                          openvdb::Vec3d worst;
                                          bad[t] = stray(acc, iso, p, worst) > max_stray;
                                      }
                                  });
            }
            if (!keep)
                keep = std::make_shared<openvdb::BoolTree>(false);
            size_t added = 0;
            std::vector<uint8_t> at_defect(points.size(), 0);
            for (uint32_t v : d.bad_vertices)
                at_defect[v] = 1;
            openvdb::tree::ValueAccessor<const openvdb::FloatTree> acc(grid->tree());
            std::vector<openvdb::Vec3d> over;
            for (size_t t = 0; t < tris.size(); t++) {
                const uint32_t *tv = tris[t].v;
                if (!bad[t] && !at_defect[tv[0]] && !at_defect[tv[1]] && !at_defect[tv[2]])
                    continue;
                const openvdb::Vec3s *p[3] = {&points[tv[0]], &points[tv[1]], &points[tv[2]]};
                // The regions holding its corners and its farthest point; after
                // the first pass (where most regions are split), every point
                // that strays, so that the few left converge in one more pass.
                openvdb::Vec3d worst;
                over.clear();
                stray(acc, iso, p, worst, max_stray, pass > 0 ? &over : nullptr);
                added += keep_voxel(*keep, worst);
                for (const openvdb::Vec3d &x : over)
                    added += keep_voxel(*keep, x);
                for (int k = 0; k < 3; k++)
                    added += keep_voxel(*keep, openvdb::Vec3d(*p[k]));
            }
            if (!added)
                break;
        }
        if (d.total() && adaptivity > 0) { // never seen; the uniform mesh is the fallback
            run_mesher(*grid, iso, 0.0, nullptr, points, tris);
            project_points(*grid, iso, points);
            d = edge_defects(tris);
        }
        if (d.total())
            fail(HV_ERR_INTERNAL, "hv_grid_to_mesh: the mesher left " + std::to_string(d.boundary) +
                                      " boundary, " + std::to_string(d.nonmanifold) +
                                      " non-manifold and " + std::to_string(d.inconsistent) +
                                      " inconsistent edges");

        // Vertices in order of first use (as readers number them), world
        // coordinates.
        std::vector<uint32_t> remap(points.size(), UINT32_MAX);
        std::vector<double> verts;
        std::vector<uint32_t> idx;
        verts.reserve(3 * points.size());
        idx.reserve(3 * tris.size());
        uint32_t nv = 0;
        for (const Tri &t : tris)
            for (int k = 0; k < 3; k++) {
                uint32_t &r = remap[t.v[k]];
                if (r == UINT32_MAX) {
                    r = nv++;
                    const openvdb::Vec3s &p = points[t.v[k]];
                    for (int a = 0; a < 3; a++)
                        verts.push_back(g->origin[a] + ((double)p[a] + 0.5) * g->h);
                }
                idx.push_back(r);
            }
        separate_coincident(verts, idx, g->h);
        return hv__mesh_from_arrays_as_is(out, verts.data(), nv, idx.data(), tris.size());
    });
}

} // extern "C"
