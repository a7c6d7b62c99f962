// Packed level-set leaves and the archive writer for them (vdb_packed.h).
#include "vdb_packed.h"
#include "vdb_internal.h"

#include <openvdb/io/Archive.h>
#include <openvdb/io/Compression.h>
#include <openvdb/io/DelayedLoadMetadata.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/io.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/NodeManager.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>

namespace hv_vdb_shim
{

namespace
{

using openvdb::Coord;
using openvdb::Index;

// A packed leaf's transient data: its id + 1 (0: not packed) and the signs of
// its first and last values after its flood fill.
constexpr uint32_t ID_BITS = 0x3fffffffu, FIRST_NEG = 1u << 30, LAST_NEG = 1u << 31;

bool serial_write()
{
    const char *s = std::getenv("HEATVOX_VDB_SERIAL_WRITE");
    return s && *s == '1';
}

// Whether a node's first (last) value is negative, as OpenVDB's
// getFirstValue() (getLastValue()) reads it, a packed leaf's from its
// transient data.
bool first_neg(const FloatLeaf &l) { return l.transientData() & FIRST_NEG; }
bool last_neg(const FloatLeaf &l) { return l.transientData() & LAST_NEG; }

template <class NodeT> bool first_neg(const NodeT &n)
{
    const auto &e = n.getTable()[0];
    return n.isChildMaskOn(0) ? first_neg(*e.getChild()) : e.getValue() < 0;
}

template <class NodeT> bool last_neg(const NodeT &n)
{
    const Index i = NodeT::NUM_VALUES - 1;
    const auto &e = n.getTable()[i];
    return n.isChildMaskOn(i) ? last_neg(*e.getChild()) : e.getValue() < 0;
}

// OpenVDB's SignedFloodFillOp (tools/SignedFloodFill.h, 10.0) above the
// leaves, reading the children's signs through first_neg and last_neg: the
// same tiles and root, with the leaves' values gone.
struct UpperFloodFill {
    using RootT = openvdb::FloatTree::RootNodeType;
    float out, in;

    void operator()(FloatLeaf &) const {} // flood-filled when packed

    template <class NodeT> void operator()(NodeT &node) const
    {
        const auto &child = node.getChildMask();
        auto *table = const_cast<typename NodeT::UnionType *>(node.getTable());
        const Index first = child.findFirstOn(), dim = 1u << NodeT::LOG2DIM;
        if (first >= NodeT::NUM_VALUES) {
            const float v = table[0].getValue() < 0 ? in : out;
            for (Index i = 0; i < NodeT::NUM_VALUES; i++)
                table[i].setValue(v);
            return;
        }
        bool x_in = first_neg(*table[first].getChild());
        for (Index x = 0; x != dim; x++) {
            const Index x00 = x << (2 * NodeT::LOG2DIM);
            if (child.isOn(x00))
                x_in = last_neg(*table[x00].getChild());
            bool y_in = x_in;
            for (Index y = 0; y != dim; y++) {
                const Index xy0 = x00 + (y << NodeT::LOG2DIM);
                if (child.isOn(xy0))
                    y_in = last_neg(*table[xy0].getChild());
                bool z_in = y_in;
                for (Index z = 0; z != dim; z++) {
                    const Index xyz = xy0 + z;
                    if (child.isOn(xyz))
                        z_in = last_neg(*table[xyz].getChild());
                    else
                        table[xyz].setValue(z_in ? in : out);
                }
            }
        }
    }

    // Inside tiles between consecutive inside children along z.
    void operator()(RootT &root) const
    {
        using ChildT = RootT::ChildNodeType;
        std::map<Coord, ChildT *> kids;
        for (auto it = root.beginChildOn(); it; ++it)
            kids.emplace(it.getCoord(), &*it);
        const int dim = (int)ChildT::DIM;
        for (auto b = kids.begin(), a = b; b != kids.end(); a = b) {
            if (++b == kids.end())
                break;
            const Coord d = b->first - a->first;
            if (d[0] != 0 || d[1] != 0 || d[2] == dim)
                continue;
            if (!last_neg(*a->second) || !first_neg(*b->second))
                continue;
            for (Coord c = a->first + Coord(0, 0, dim); c[2] != b->first[2]; c[2] += dim)
                root.addTile(c, in, false);
        }
        root.setBackground(out, /*updateChildNodes=*/false);
    }
};

// The bytes of a leaf's values in the file, past its value mask, before its
// compressed array: the mask-compression byte, the inactive values it names
// and the mask selecting between two of them (io::writeCompressedValues).
size_t value_header_bytes(int8_t meta)
{
    using namespace openvdb::io;
    size_t n = 1;
    if (meta == NO_MASK_AND_ONE_INACTIVE_VAL || meta == MASK_AND_ONE_INACTIVE_VAL)
        n += sizeof(float);
    if (meta == MASK_AND_TWO_INACTIVE_VALS)
        n += 2 * sizeof(float);
    if (meta == MASK_AND_NO_INACTIVE_VALS || meta == MASK_AND_ONE_INACTIVE_VAL ||
        meta == MASK_AND_TWO_INACTIVE_VALS)
        n += FloatLeaf::NodeMaskType::memUsage();
    return n;
}

// Archive::write's protected parts, for write_archive.
class PackedArchive : public openvdb::io::Archive
{
  public:
    void write_all(std::ostream &os, const openvdb::GridCPtrVec &grids,
                   const openvdb::MetaMap &meta) const;

  private:
    void write_packed(openvdb::io::GridDescriptor &gd, const LevelsetGrid &grid, std::ostream &os,
                      openvdb::io::StreamMetadata::Ptr &outer) const;
};

// Archive::write (io/Archive.cc, 10.0) for heatvox's grids: names unique and
// not empty, no tree shared, seekable. Packed level sets go through
// write_packed, the others through OpenVDB's own writeGrid.
void PackedArchive::write_all(std::ostream &os, const openvdb::GridCPtrVec &grids,
                              const openvdb::MetaMap &meta) const
{
    using namespace openvdb::io;
    StreamMetadata::Ptr sm = openvdb::io::getStreamMetadataPtr(os);
    if (!sm) {
        sm = std::make_shared<StreamMetadata>();
        openvdb::io::setStreamMetadataPtr(os, sm, /*transfer=*/false);
    }
    openvdb::io::setDataCompression(os, compression());
    openvdb::io::setWriteGridStatsMetadata(os, isGridStatsMetadataEnabled());
    writeHeader(os, /*seekable=*/true);
    meta.writeMeta(os);
    int32_t count = 0;
    for (const auto &g : grids)
        count += g != nullptr;
    os.write(reinterpret_cast<const char *>(&count), sizeof count);
    for (const auto &g : grids) {
        if (!g)
            continue;
        GridDescriptor gd(g->getName(), g->type(), g->saveFloatAsHalf());
        auto *ls = dynamic_cast<const LevelsetGrid *>(g.get());
        if (ls && ls->packed_leaves())
            write_packed(gd, *ls, os, sm);
        else
            writeGrid(gd, g, os, /*seekable=*/true);
        openvdb::io::setDataCompression(os, compression());
    }
}

// Archive::writeGrid with the delayed-load metadata from the packed bytes
// and the statistics of the unpacked tree: the same bytes.
void PackedArchive::write_packed(openvdb::io::GridDescriptor &gd, const LevelsetGrid &grid,
                                 std::ostream &os, openvdb::io::StreamMetadata::Ptr &outer) const
{
    using namespace openvdb::io;
    auto sm = std::make_shared<StreamMetadata>(outer ? *outer : StreamMetadata());
    sm->setHalfFloat(grid.saveFloatAsHalf());
    sm->gridMetadata() = static_cast<const openvdb::MetaMap &>(grid);
    openvdb::io::setStreamMetadataPtr(os, sm, /*transfer=*/false);
    gd.writeHeader(os);
    const std::streampos offsets = os.tellp();
    gd.writeStreamPos(os);
    gd.setGridPos(os.tellp());
    setGridCompression(os, grid);
    if (openvdb::io::getDataCompression(os) != file_compression() ||
        compression() != file_compression())
        fail(HV_ERR_INTERNAL,
             "level set '" + grid.getName() + "': its leaves were packed for another compression");

    openvdb::MetaMap meta(static_cast<const openvdb::MetaMap &>(grid));
    DelayedLoadMetadata dl;
    grid.delayed_load_meta(dl);
    meta.insertMeta(openvdb::GridBase::META_FILE_DELAYED_LOAD, dl);
    if (openvdb::io::getWriteGridStatsMetadata(os)) {
        const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
        meta.insertMeta(openvdb::GridBase::META_FILE_BBOX_MIN,
                        openvdb::Vec3IMetadata(box.min().asVec3i()));
        meta.insertMeta(openvdb::GridBase::META_FILE_BBOX_MAX,
                        openvdb::Vec3IMetadata(box.max().asVec3i()));
        meta.insertMeta(openvdb::GridBase::META_FILE_MEM_BYTES,
                        openvdb::Int64Metadata((int64_t)grid.unpacked_mem_usage()));
        meta.insertMeta(openvdb::GridBase::META_FILE_VOXEL_COUNT,
                        openvdb::Int64Metadata((int64_t)grid.activeVoxelCount()));
        meta.insertMeta(openvdb::GridBase::META_FILE_COMPRESSION,
                        openvdb::StringMetadata(
                            openvdb::io::compressionToString(openvdb::io::getDataCompression(os))));
    }
    meta.writeMeta(os);
    grid.writeTransform(os);
    grid.writeTopology(os);
    gd.setBlockPos(os.tellp());
    grid.writeBuffers(os);
    gd.setEndPos(os.tellp());
    os.seekp(offsets, std::ios_base::beg);
    gd.writeStreamPos(os);
    gd.seekToEnd(os);
    openvdb::io::setStreamMetadataPtr(os, outer, /*transfer=*/false);
}

} // namespace

uint32_t file_compression()
{
    using namespace openvdb::io;
    return COMPRESS_ACTIVE_MASK | (Archive::hasBloscCompression() ? COMPRESS_BLOSC : COMPRESS_ZIP);
}

bool LevelsetGrid::can_pack()
{
    return !serial_write() && openvdb::io::Archive::hasBloscCompression();
}

LevelsetGrid::LevelsetGrid(float bg, bool packing)
    : openvdb::FloatGrid(bg), packing_(packing && can_pack())
{
}

size_t LevelsetGrid::reserve_packed(size_t n)
{
    const size_t base = bytes_.size();
    if (base + n >= ID_BITS)
        fail(HV_ERR_NOMEM, "level set '" + getName() + "': more leaves than can be packed");
    bytes_.resize(base + n);
    return base;
}

std::ostringstream LevelsetGrid::packing_stream() const
{
    std::ostringstream ss;
    openvdb::io::setDataCompression(ss, file_compression());
    return ss;
}

void LevelsetGrid::pack(FloatLeaf &leaf, size_t id, std::ostringstream &ss)
{
    const float bg = tree().background();
    openvdb::tools::SignedFloodFillOp<openvdb::FloatTree> fill(bg, -bg);
    fill(leaf);
    const float *v = leaf.buffer().data();
    uint32_t t = (uint32_t)(id + 1);
    t |= v[0] < 0 ? FIRST_NEG : 0;
    t |= v[FloatLeaf::SIZE - 1] < 0 ? LAST_NEG : 0;
    openvdb::io::setGridBackgroundValuePtr(ss, &bg);
    ss.str(std::string());
    leaf.writeBuffers(ss, /*toHalf=*/false);
    bytes_[id] = ss.str();
    FloatLeaf::Buffer none(openvdb::PartialCreate(), 0.0f); // no values
    leaf.swap(none);
    leaf.setTransientData(t);
}

const std::string *LevelsetGrid::packed_bytes_of(const FloatLeaf &leaf) const
{
    const uint32_t id = leaf.transientData() & ID_BITS;
    return id ? &bytes_[id - 1] : nullptr;
}

void LevelsetGrid::flood_fill()
{
    if (!packed_leaves()) {
        openvdb::tools::signedFloodFill(tree());
        return;
    }
    const float bg = std::fabs(tree().background());
    openvdb::tree::NodeManager<openvdb::FloatTree> nodes(tree());
    nodes.foreachBottomUp(UpperFloodFill{bg, -bg});
}

double LevelsetGrid::packed_bytes() const
{
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, bytes_.size()), 0.0,
        [&](const tbb::blocked_range<size_t> &r, double s) {
            for (size_t i = r.begin(); i != r.end(); i++)
                s += (double)bytes_[i].capacity();
            return s;
        },
        [](double a, double b) { return a + b; });
}

openvdb::Index64 LevelsetGrid::unpacked_mem_usage() const
{
    return memUsage() + (openvdb::Index64)packed_leaves() * FloatLeaf::SIZE * sizeof(float);
}

void LevelsetGrid::delayed_load_meta(openvdb::io::DelayedLoadMetadata &dl) const
{
    const size_t n = tree().leafCount();
    dl.resizeMask(n);
    dl.resizeCompressedSize(n);
    const size_t mask_bytes = FloatLeaf::NodeMaskType::memUsage();
    size_t i = 0;
    for (auto it = tree().cbeginLeaf(); it; ++it, ++i) {
        const std::string *b = packed_bytes_of(*it.getLeaf());
        if (!b || b->size() <= mask_bytes)
            fail(HV_ERR_INTERNAL, "level set '" + getName() + "': a leaf was not packed");
        const int8_t meta = (int8_t)(*b)[mask_bytes];
        const size_t head = mask_bytes + value_header_bytes(meta);
        if (b->size() <= head)
            fail(HV_ERR_INTERNAL, "level set '" + getName() + "': a packed leaf is cut short");
        dl.setMask(i, meta);
        dl.setCompressedSize(i, (int64_t)(b->size() - head));
    }
}

// Grid::writeBuffers' bytes: the packed leaves' as they are, the others'
// compressed on all cores a batch of leaves at a time, written in the tree's
// order (each leaf's bytes depend only on the leaf, the stream's compression
// and the background). OpenVDB's own writes leaf by leaf on one core.
void LevelsetGrid::writeBuffers(std::ostream &os) const
{
    if (saveFloatAsHalf() || serial_write()) {
        if (packed_leaves())
            fail(HV_ERR_INTERNAL, "level set '" + getName() + "': its leaves are packed");
        openvdb::FloatGrid::writeBuffers(os);
        return;
    }
    std::vector<const FloatLeaf *> leaves;
    leaves.reserve(tree().leafCount());
    for (auto it = tree().cbeginLeaf(); it; ++it)
        leaves.push_back(it.getLeaf());
    const uint32_t comp = openvdb::io::getDataCompression(os);
    const void *bg = openvdb::io::getGridBackgroundValuePtr(os);
    const size_t batch = 8192;
    std::vector<std::string> made(std::min(batch, leaves.size()));
    for (size_t b0 = 0; b0 < leaves.size(); b0 += batch) {
        const size_t b1 = std::min(b0 + batch, leaves.size());
        tbb::parallel_for(tbb::blocked_range<size_t>(b0, b1),
                          [&](const tbb::blocked_range<size_t> &r) {
                              std::ostringstream ss;
                              openvdb::io::setDataCompression(ss, comp);
                              openvdb::io::setGridBackgroundValuePtr(ss, bg);
                              for (size_t l = r.begin(); l != r.end(); l++) {
                                  if (packed_bytes_of(*leaves[l]))
                                      continue;
                                  ss.str(std::string());
                                  leaves[l]->writeBuffers(ss, false);
                                  made[l - b0] = ss.str();
                              }
                          });
        for (size_t l = b0; l < b1; l++) {
            const std::string *b = packed_bytes_of(*leaves[l]);
            if (!b)
                b = &made[l - b0];
            os.write(b->data(), (std::streamsize)b->size());
        }
    }
}

void write_archive(std::ostream &os, const openvdb::GridCPtrVec &grids,
                   const openvdb::MetaMap &meta)
{
    PackedArchive ar;
    ar.setCompression(file_compression());
    ar.write_all(os, grids, meta);
}

} // namespace hv_vdb_shim
