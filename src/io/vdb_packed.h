// Private to the OpenVDB shim (vdb_write.cpp, vdb_packed.cpp): level sets
// whose leaves are packed as soon as their voxels are final. A packed leaf
// keeps its value mask; its values live on only as the bytes the .vdb holds
// for them (OpenVDB's LeafNode::writeBuffers with the file's compression),
// made on all cores while the band is still being computed. The archive
// writer here writes those bytes where OpenVDB's would compress the values.
#ifndef HV_IO_VDB_PACKED_H
#define HV_IO_VDB_PACKED_H

#include <openvdb/openvdb.h>

#include <cstdint>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace hv_vdb_shim
{

using FloatLeaf = openvdb::FloatTree::LeafNodeType;

// The compression heatvox writes .vdb files with: active-mask compression
// and Blosc (zlib where OpenVDB was built without Blosc).
uint32_t file_compression();

// A float level set of background bg (> 0) whose leaves are compressed on all
// cores. With packing on, the leaves handed to pack() are packed: their own
// signed flood fill, then their bytes, then their values freed; the tree's
// other levels are flood-filled by flood_fill() from the packed leaves'
// first and last signs, as OpenVDB's signedFloodFill does from the values.
// Packing is off with HEATVOX_VDB_SERIAL_WRITE=1 (OpenVDB's own flood fill
// and writer throughout, for tests) and without Blosc.
class LevelsetGrid final : public openvdb::FloatGrid
{
  public:
    using Ptr = std::shared_ptr<LevelsetGrid>;
    LevelsetGrid(float bg, bool packing);
    static bool can_pack(); // not HEATVOX_VDB_SERIAL_WRITE=1, and Blosc
    bool packing() const { return packing_; }

    // Ids for n more leaves to pack, the first returned; one caller at a time.
    size_t reserve_packed(size_t n);
    // A stream to pack with, one per thread.
    std::ostringstream packing_stream() const;
    // Packs leaf (its voxels final, not yet packed) under an id from
    // reserve_packed; safe from several threads for distinct leaves and ids.
    void pack(FloatLeaf &leaf, size_t id, std::ostringstream &ss);

    // The signed flood fill of the whole tree, once every leaf is in it.
    void flood_fill();

    size_t packed_leaves() const { return bytes_.size(); }
    double packed_bytes() const;
    // The tree's memory were its packed leaves' values still held (OpenVDB's
    // memUsage, as the file's statistics give it).
    openvdb::Index64 unpacked_mem_usage() const;
    // The .vdb's delayed-load metadata of this grid, as OpenVDB's
    // Archive::writeGrid makes it from the values. Packed grids only.
    void delayed_load_meta(openvdb::io::DelayedLoadMetadata &dl) const;

    void writeBuffers(std::ostream &os) const override;

  private:
    const std::string *packed_bytes_of(const FloatLeaf &leaf) const;

    bool packing_;
    std::vector<std::string> bytes_; // by id
};

// Writes grids with the file's metadata to os as OpenVDB's Archive::write
// does (seekable, compression file_compression()); a packed level set's
// delayed-load metadata comes from its bytes. The caller owns the stream and
// checks it once closed (File::write opens its own and never checks it after
// closing, so a full disk would go unnoticed).
void write_archive(std::ostream &os, const openvdb::GridCPtrVec &grids,
                   const openvdb::MetaMap &meta);

} // namespace hv_vdb_shim

#endif
