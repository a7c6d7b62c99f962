/* Private to the OpenVDB shim (vdb_read.cpp): checks the layout of a .vdb file
 * against the file's size before OpenVDB reads it. OpenVDB trusts every length
 * and count it reads (a string length, a metadata size, a node count, a
 * compressed block size) and keeps reading after the end of a truncated file
 * with whatever its variables held, so a cut or damaged file can make it
 * allocate and fill gigabytes. The check walks the same layout OpenVDB reads
 * (io/Archive.cc, io/GridDescriptor.cc, MetaMap.cc, math/Transform.cc,
 * tree/RootNode.h, InternalNode.h, LeafNode*.h, io/Compression.h of OpenVDB 10,
 * file formats 222 to 224) without allocating from what it reads. */
#ifndef HV_IO_VDB_CHECK_H
#define HV_IO_VDB_CHECK_H

#include "heatvox/core.h"

#include <memory>
#include <string>

namespace hv_vdb_check
{

/* Why a file must not be handed to OpenVDB. st is HV_ERR_IO for a file that
 * cannot be read or is truncated or corrupt, HV_ERR_UNSUPPORTED for a format
 * version or grid type the check does not know; msg starts with the path. */
struct Rejected {
    hv_status st;
    std::string msg;
};

class FileCheck
{
  public:
    /* Checks the header, the file metadata, every grid descriptor (names,
     * types, positions within the file and in order) and every grid's
     * metadata and transform; a file without grid offsets (read whole by
     * OpenVDB on open) also has every tree checked. Throws Rejected. Needs
     * openvdb::initialize() done (it asks OpenVDB's metadata registry). */
    explicit FileCheck(const std::string &path);
    ~FileCheck();
    FileCheck(const FileCheck &) = delete;
    FileCheck &operator=(const FileCheck &) = delete;

    /* Checks the topology and the value blocks of every grid that
     * openvdb::io::File::readGrid(name) may read: the grids of that name (or
     * "name[N]") and their instance parents. Each tree is checked once.
     * Throws Rejected. */
    void check_tree(const std::string &name);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace hv_vdb_check

#endif
