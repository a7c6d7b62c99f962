// OpenVDB's tools::VolumeToMesh, alone in this file: its templates are most
// of what compiling the mesher takes, and the sanitized builds compile this
// file as OpenVDB itself is compiled, without instrumentation (Makefile,
// VDB_ALGO_SRC). What heatvox does with the polygons is in vdb_mesh.cpp.
#include "vdb_volmesh.h"

#include <openvdb/tools/VolumeToMesh.h>

namespace hv_vdb_shim
{

void volume_to_mesh(const openvdb::FloatGrid &grid, float iso, double adaptivity,
                    const openvdb::BoolTree::Ptr &keep, std::vector<openvdb::Vec3s> &points,
                    std::vector<openvdb::Vec4I> &quads, std::vector<openvdb::Vec3I> &triangles)
{
    openvdb::tools::VolumeToMesh mesher(iso, adaptivity, true);
    if (keep)
        mesher.setAdaptivityMask(keep);
    mesher(grid);
    points.assign(mesher.pointList().get(), mesher.pointList().get() + mesher.pointListSize());
    quads.clear();
    triangles.clear();
    openvdb::tools::PolygonPoolList &pools = mesher.polygonPoolList();
    for (size_t p = 0; p < mesher.polygonPoolListSize(); p++) {
        const openvdb::tools::PolygonPool &pool = pools[p];
        for (size_t i = 0; i < pool.numQuads(); i++)
            quads.push_back(pool.quad(i));
        for (size_t i = 0; i < pool.numTriangles(); i++)
            triangles.push_back(pool.triangle(i));
    }
}

} // namespace hv_vdb_shim
