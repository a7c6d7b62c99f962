// OpenVDB's mesher on its own (vdb_volmesh.cpp), for vdb_mesh.cpp.
#ifndef HV_MESH_VDB_VOLMESH_H
#define HV_MESH_VDB_VOLMESH_H

#include <openvdb/openvdb.h>

#include <vector>

namespace hv_vdb_shim
{

// One run of tools::VolumeToMesh on grid at iso (adaptivity in [0, 1], keep
// the adaptivity mask or null): its points (index space), quads and
// triangles as OpenVDB gives them.
void volume_to_mesh(const openvdb::FloatGrid &grid, float iso, double adaptivity,
                    const openvdb::BoolTree::Ptr &keep, std::vector<openvdb::Vec3s> &points,
                    std::vector<openvdb::Vec4I> &quads, std::vector<openvdb::Vec3I> &triangles);

} // namespace hv_vdb_shim

#endif
