// The .vdb layout check of vdb_check.h. It reads the file through a small
// window and skips what it does not need; nothing it allocates depends on a
// length read from the file beyond that length having been found inside the
// file (names, and one uint16 per leaf for the leaves whose masks it read).
#include "vdb_check.h"

#include <openvdb/Metadata.h>
#include <openvdb/version.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace hv_vdb_check
{
namespace
{

const int64_t VDB_MAGIC = 0x56444220;
// OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION (OpenVDB 2.0, 2013): per-grid
// compression flags and per-node value compression codes. Older layouts
// (pre-2.0 root and leaf formats) are refused rather than half checked.
const uint32_t FIRST_VERSION = 222;

// Per-grid compression flags (io/Compression.h).
const uint32_t COMP_ZIP = 0x1, COMP_ACTIVE_MASK = 0x2, COMP_BLOSC = 0x4;

// The code byte before each node's values (io/Compression.h).
enum {
    NO_MASK_OR_INACTIVE_VALS,
    NO_MASK_AND_MINUS_BG,
    NO_MASK_AND_ONE_INACTIVE_VAL,
    MASK_AND_NO_INACTIVE_VALS,
    MASK_AND_ONE_INACTIVE_VAL,
    MASK_AND_TWO_INACTIVE_VALS,
    NO_MASK_AND_ALL_VALS
};

const uint64_t BLOSC_HEADER = 16;
const uint64_t BLOSC_PAD_BYTES = 128; // points/StreamCompression.h: small buffers are padded
const uint64_t LEAF_MASK_BYTES = 64;  // an 8^3 leaf's mask; every leaf has one in the topology
const uint32_t LEAF_VALUES = 512;
const int32_t ROOT_CHILD_DIM = 4096; // 2^(5+4+3): root children sit on this lattice

// GridBase::META_SAVE_HALF_FLOAT. Archive::readGrid sets it from the
// descriptor's "_HalfFloat" suffix, then GridBase::readMeta clears the map and
// reads the file's: the trees are read as half floats when the grid's own
// metadata says so (Metadata::asBool() of the entry of this name), whatever
// the suffix says.
const char *const HALF_FLOAT_META = "is_saved_as_half_float";

std::string num(uint64_t v) { return std::to_string(v); }

// Names from a damaged file may hold anything: print them escaped and short.
std::string shown(const std::string &s)
{
    std::string out;
    for (size_t i = 0; i < s.size() && out.size() < 80; i++) {
        const unsigned char c = (unsigned char)s[i];
        if (c >= 0x20 && c < 0x7f && c != '\\') {
            out += (char)c;
        } else {
            char b[8];
            snprintf(b, sizeof b, "\\x%02x", c);
            out += b;
        }
    }
    if (out.size() >= 80)
        out += "...";
    return out;
}

// OpenVDB's unique names are "name" or "name\x1eN" (GridDescriptor::addSuffix);
// users see "name[N]".
std::string grid_label(const std::string &unique)
{
    const size_t sep = unique.find('\x1e');
    if (sep == std::string::npos)
        return shown(unique);
    return shown(unique.substr(0, sep)) + "[" + shown(unique.substr(sep + 1)) + "]";
}

unsigned popcount(const uint8_t *p, size_t bytes)
{
    unsigned n = 0;
    for (size_t i = 0; i < bytes; i += 8) {
        uint64_t w;
        memcpy(&w, p + i, 8);
        n += (unsigned)__builtin_popcountll(w);
    }
    return n;
}

uint32_t le32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

// The file through a window of WINDOW bytes. `end` is the end of the region
// being walked (the file, a grid, its topology, one metadata value): nothing
// at or after it is ever read, and a field that would cross it is an error.
class Reader
{
  public:
    explicit Reader(const std::string &path) : path_(path), buf_(WINDOW)
    {
        fd_ = open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (fd_ < 0)
            throw Rejected{HV_ERR_IO, path + ": cannot open: " + strerror(errno)};
        struct stat st;
        if (fstat(fd_, &st) != 0) {
            const int e = errno;
            close(fd_);
            throw Rejected{HV_ERR_IO, path + ": cannot stat: " + strerror(e)};
        }
        if (!S_ISREG(st.st_mode)) {
            close(fd_);
            throw Rejected{HV_ERR_IO, path + ": not a regular file"};
        }
        size_ = (uint64_t)st.st_size;
        end = size_;
    }
    ~Reader() { close(fd_); }
    Reader(const Reader &) = delete;
    Reader &operator=(const Reader &) = delete;

    const std::string &path() const { return path_; }
    uint64_t size() const { return size_; }

    uint64_t pos = 0;
    uint64_t end = 0;
    std::string region; // what ends at `end` when that is not the end of the file
    std::string ctx;    // what is being read, e.g. "grid 'sdf' topology: "

    [[noreturn]] void corrupt(const std::string &what) const
    {
        throw Rejected{HV_ERR_IO, path_ + ": corrupt: " + ctx + what};
    }

    // [pos, pos + n) must lie in the region. `length`: n was read from the
    // file (a size or a count), so it may be the damaged part.
    void need(uint64_t n, const char *what, bool length) const
    {
        if (pos <= end && n <= end - pos)
            return;
        const bool file_end = end == size_;
        std::string m = path_ + ": ";
        m += !file_end ? "corrupt: " : length ? "truncated or corrupt: " : "truncated: ";
        m += ctx + what;
        if (length)
            m += " of " + num(n) + " bytes";
        m += " at byte " + num(pos) + " runs past ";
        m += file_end ? "the end of the file (" + num(size_) + " bytes)"
                      : "the end of " + region + " (byte " + num(end) + ")";
        throw Rejected{HV_ERR_IO, m};
    }

    // n <= WINDOW bytes; the pointer is valid until the next read.
    const uint8_t *take(uint64_t n, const char *what)
    {
        need(n, what, false);
        if (pos < win_off_ || pos + n > win_off_ + win_len_)
            fill(n);
        const uint8_t *p = buf_.data() + (pos - win_off_);
        pos += n;
        return p;
    }

    void skip(uint64_t n, const char *what, bool length)
    {
        need(n, what, length);
        pos += n;
    }

    uint8_t u8(const char *what) { return *take(1, what); }
    uint32_t u32(const char *what)
    {
        uint32_t v;
        memcpy(&v, take(4, what), 4);
        return v;
    }
    int32_t i32(const char *what)
    {
        int32_t v;
        memcpy(&v, take(4, what), 4);
        return v;
    }
    int64_t i64(const char *what)
    {
        int64_t v;
        memcpy(&v, take(8, what), 8);
        return v;
    }

    // openvdb::readString: a uint32 length, then the bytes.
    std::string str(const char *what)
    {
        const uint32_t len = u32(what);
        need(len, what, true);
        std::string s;
        s.reserve(len);
        while (s.size() < len) {
            const uint64_t chunk = std::min<uint64_t>(len - s.size(), WINDOW);
            s.append(reinterpret_cast<const char *>(take(chunk, what)), (size_t)chunk);
        }
        return s;
    }

  private:
    static constexpr uint64_t WINDOW = 1 << 16;

    void fill(uint64_t n)
    {
        const uint64_t want = std::min<uint64_t>(WINDOW, size_ - pos);
        uint64_t got = 0;
        int err = 0;
        while (got < want) {
            const ssize_t r =
                pread(fd_, buf_.data() + got, (size_t)(want - got), (off_t)(pos + got));
            if (r < 0 && errno == EINTR)
                continue;
            if (r <= 0) {
                err = r < 0 ? errno : 0;
                break;
            }
            got += (uint64_t)r;
        }
        win_off_ = pos;
        win_len_ = got;
        if (got < n)
            throw Rejected{HV_ERR_IO,
                           path_ + ": cannot read byte " + num(pos + got) + ": " +
                               (err ? strerror(err) : "the file got shorter while being read")};
    }

    std::string path_;
    int fd_ = -1;
    uint64_t size_ = 0;
    std::vector<uint8_t> buf_;
    uint64_t win_off_ = 0, win_len_ = 0;
};

// Tree value types this check walks: the registered 5-4-3 trees other than
// the point grids. half: bytes per value when saved as half float (real
// types only, io::RealToHalf), else 0.
enum LeafKind { LEAF_PLAIN, LEAF_BOOL, LEAF_MASK };
struct ValueKind {
    const char *name;
    uint32_t size;
    uint32_t half;
    LeafKind leaf;
};
const ValueKind VALUE_KINDS[] = {
    {"float", 4, 2, LEAF_PLAIN},  {"double", 8, 2, LEAF_PLAIN}, {"int32", 4, 0, LEAF_PLAIN},
    {"int64", 8, 0, LEAF_PLAIN},  {"vec3i", 12, 0, LEAF_PLAIN}, {"vec3s", 12, 6, LEAF_PLAIN},
    {"vec3d", 24, 6, LEAF_PLAIN}, {"bool", 1, 0, LEAF_BOOL},    {"mask", 1, 0, LEAF_MASK},
};

const ValueKind *value_kind(const std::string &grid_type)
{
    const std::string pre = "Tree_", post = "_5_4_3";
    if (grid_type.size() <= pre.size() + post.size() || grid_type.compare(0, pre.size(), pre) ||
        grid_type.compare(grid_type.size() - post.size(), post.size(), post))
        return nullptr;
    const std::string v = grid_type.substr(pre.size(), grid_type.size() - pre.size() - post.size());
    for (const ValueKind &k : VALUE_KINDS)
        if (v == k.name)
            return &k;
    return nullptr;
}

struct Grid {
    std::string unique; // as stored, "name" or "name\x1eN"
    std::string name;   // without the suffix: what File::findDescriptor matches
    std::string label;  // for messages
    std::string type;   // without "_HalfFloat"
    std::string parent; // unique name of the instance parent, or empty
    bool half = false;  // values saved as half floats: HALF_FLOAT_META, not the type's suffix
    uint64_t grid_pos = 0, block_pos = 0, end_pos = 0; // with grid offsets only
    uint64_t tree_pos = 0; // where the topology starts (after the transform)
    uint32_t compression = 0;
    bool tree_checked = false;
};

struct Tree {
    const ValueKind *kind;
    bool half;
    uint32_t compression;
    uint64_t leaves = 0;
    std::vector<uint16_t> leaf_active; // active voxels of each plain leaf, in file order
};

} // namespace

struct FileCheck::Impl {
    Reader r;
    uint32_t version = 0;
    bool offsets = true;
    std::vector<Grid> grids;
    std::unordered_map<std::string, size_t> by_unique; // index into grids

    explicit Impl(const std::string &path) : r(path) {}

    [[noreturn]] void unsupported(const std::string &what) const
    {
        throw Rejected{HV_ERR_UNSUPPORTED, r.path() + ": " + what};
    }

    void set_region(uint64_t end, const std::string &region)
    {
        r.end = end;
        r.region = region;
    }

    // io::Archive::readHeader, from format 222 on.
    void header()
    {
        r.ctx = "header: ";
        if (r.size() == 0)
            throw Rejected{HV_ERR_IO, r.path() + ": empty file, not an OpenVDB file"};
        if (r.size() < 8 || r.i64("magic number") != VDB_MAGIC)
            throw Rejected{HV_ERR_IO, r.path() + ": not an OpenVDB file (no VDB magic number)"};
        version = r.u32("file format version");
        if (version < FIRST_VERSION || version > openvdb::OPENVDB_FILE_VERSION)
            unsupported("OpenVDB file format " + num(version) +
                        " is not supported (heatvox reads formats " + num(FIRST_VERSION) + " to " +
                        num(openvdb::OPENVDB_FILE_VERSION) + ", OpenVDB 2.0 and later)");
        r.u32("library major version");
        r.u32("library minor version");
        offsets = r.u8("grid offsets flag") != 0;
        // The UUID as 36 characters (boost::uuids operator>>).
        const uint8_t *u = r.take(36, "UUID");
        for (int i = 0; i < 36; i++) {
            const bool dash = i == 8 || i == 13 || i == 18 || i == 23;
            if (dash ? u[i] != '-' : !isxdigit(u[i]))
                r.corrupt("the UUID at byte " + num(r.pos - 36) +
                          " is not 36 hex digits and dashes");
        }
    }

    // MetaMap::readMeta. leaf_bound caps the leaf count of delayed-load
    // metadata (one 64-byte mask per leaf must fit in the grid). half (grid
    // metadata only): set to what GridBase::saveFloatAsHalf() will return
    // once OpenVDB has read this map, see HALF_FLOAT_META.
    void metamap(uint64_t leaf_bound, bool *half = nullptr)
    {
        const std::string base = r.ctx;
        if (half)
            *half = false; // MetaMap::readMeta clears the map first
        const uint32_t count = r.u32("metadata count");
        for (uint32_t i = 0; i < count; i++) {
            r.ctx = base + "entry " + num(i + 1) + " of " + num(count) + ": ";
            const std::string name = r.str("name");
            r.ctx = base + "'" + shown(name) + "': ";
            const std::string type = r.str("type name");
            const uint32_t nbytes = r.u32("value size");
            r.need(nbytes, "value", true);
            const bool half_flag = half && name == HALF_FLOAT_META;
            if (type == "__delayedload") {
                if (half_flag)
                    r.corrupt("the half-float flag stored as " + shown(type) + " metadata");
                delayed_load(nbytes, leaf_bound);
            } else if (type != "string" && openvdb::Metadata::isRegisteredType(type)) {
                // TypedMetadata::readValue reads sizeof(T) whatever the
                // stored size says; a different size puts OpenVDB off track.
                openvdb::Metadata::Ptr meta = openvdb::Metadata::createMetadata(type);
                const uint32_t want = meta->size();
                if (nbytes != want)
                    r.corrupt("a " + shown(type) + " value of " + num(nbytes) + " bytes (it has " +
                              num(want) + ")");
                if (half_flag) {
                    // Metadata::asBool() of the value as OpenVDB reads it.
                    const uint8_t *v = r.take(nbytes, "value");
                    if (type == "bool") {
                        *half = v[0] != 0;
                    } else {
                        std::string bytes(4 + (size_t)nbytes, '\0');
                        memcpy(&bytes[0], &nbytes, 4);
                        memcpy(&bytes[4], v, nbytes);
                        std::istringstream in(bytes);
                        meta->read(in);
                        *half = meta->asBool();
                    }
                } else {
                    r.skip(nbytes, "value", true);
                }
            } else {
                // A string (asBool: not empty), or kept as raw bytes by
                // UnknownMetadata (asBool: not empty) unless its type name
                // starts with "__" (dropped by readMeta).
                if (half_flag && (type == "string" || type.compare(0, 2, "__") != 0))
                    *half = nbytes > 0;
                r.skip(nbytes, "value", true);
            }
        }
        r.ctx = base;
    }

    // A Blosc block: OpenVDB allocates n bytes, and Blosc reads as many
    // compressed bytes as its header says and writes as many as it says.
    void blosc_block(uint64_t n, uint64_t expect, bool padded, const char *what)
    {
        r.need(n, what, true);
        if (n < BLOSC_HEADER)
            r.corrupt(std::string(what) + " at byte " + num(r.pos) + ": a Blosc block of " +
                      num(n) + " bytes, shorter than its header");
        const uint64_t at = r.pos;
        const uint8_t *h = r.take(BLOSC_HEADER, what);
        const uint32_t nbytes = le32(h + 4), cbytes = le32(h + 12);
        if (nbytes != expect && !(padded && expect < BLOSC_PAD_BYTES && nbytes == BLOSC_PAD_BYTES))
            r.corrupt(std::string(what) + " at byte " + num(at) + ": a Blosc block of " +
                      num(nbytes) + " bytes where " + num(expect) + " are expected");
        if (cbytes < BLOSC_HEADER || cbytes > n)
            r.corrupt(std::string(what) + " at byte " + num(at) + ": a Blosc block of " + num(n) +
                      " bytes whose header claims " + num(cbytes));
        r.skip(n - BLOSC_HEADER, what, true);
    }

    // io::DelayedLoadMetadata::readValue: a leaf count, then per-leaf masks
    // (1 byte) and compressed sizes (8 bytes), each block raw or Blosc.
    void delayed_load(uint32_t nbytes, uint64_t leaf_bound)
    {
        if (nbytes == 0)
            return;
        const uint64_t stop = r.pos + nbytes, outer_end = r.end;
        const std::string outer_region = r.region;
        set_region(stop, "this metadata value");
        const uint32_t count = r.u32("leaf count");
        if (count > leaf_bound)
            r.corrupt("a leaf count of " + num(count) +
                      ", more leaves than the grid's bytes can hold (" + num(leaf_bound) + ")");
        const uint32_t mask_bytes = r.u32("leaf mask block size");
        if (mask_bytes > 0)
            blosc_block(mask_bytes, count, true, "leaf masks");
        else
            r.skip(count, "leaf masks", true);
        const uint32_t size_bytes = r.u32("leaf size block size");
        if (size_bytes != UINT32_MAX) {
            if (size_bytes > 0)
                blosc_block(size_bytes, 8ull * count, true, "leaf sizes");
            else
                r.skip(8ull * count, "leaf sizes", true);
        }
        r.pos = stop; // OpenVDB skips what it does not know
        set_region(outer_end, outer_region);
    }

    // math::Transform::read (format 219 on) and the maps' read().
    void map(const std::string &type, bool nested)
    {
        uint64_t n;
        if (type == "AffineMap" || type == "UnitaryMap")
            n = 128; // Mat4d
        else if (type == "ScaleMap" || type == "UniformScaleMap")
            n = 5 * 24; // five Vec3d
        else if (type == "TranslationMap")
            n = 24;
        else if (type == "ScaleTranslateMap" || type == "UniformScaleTranslateMap")
            n = 6 * 24;
        else if (type == "NonlinearFrustumMap" && !nested) {
            r.skip(48 + 8 + 8, "frustum box, taper and depth", false);
            map(r.str("frustum's linear map type"), true);
            return;
        } else
            r.corrupt("unknown transform map type '" + shown(type) + "'");
        r.skip(n, "map", false);
    }

    // Archive::readGridCompression, GridBase::readMeta and readTransform.
    void grid_head(Grid &g)
    {
        r.ctx = "grid '" + g.label + "': ";
        g.compression = r.u32("compression flags");
        if (g.compression & ~(COMP_ZIP | COMP_ACTIVE_MASK | COMP_BLOSC))
            r.corrupt("unknown compression flags 0x" + [&] {
                char b[16];
                snprintf(b, sizeof b, "%x", g.compression);
                return std::string(b);
            }());
        r.ctx = "grid '" + g.label + "' metadata: ";
        metamap((r.end - r.pos) / LEAF_MASK_BYTES, &g.half);
        r.ctx = "grid '" + g.label + "' transform: ";
        map(r.str("map type"), false);
        g.tree_pos = r.pos;
        r.ctx = "grid '" + g.label + "': ";
        if (offsets && !g.parent.empty() && r.pos != g.end_pos)
            r.corrupt("an instance whose metadata and transform end at byte " + num(r.pos) +
                      ", not at its recorded end (byte " + num(g.end_pos) + ")");
        if (offsets && g.parent.empty() && r.pos > g.block_pos)
            r.corrupt("its metadata and transform end at byte " + num(r.pos) +
                      ", past its recorded data position (byte " + num(g.block_pos) + ")");
    }

    // File::open: the grid count, then each descriptor (GridDescriptor::read).
    void descriptors()
    {
        r.ctx = "";
        const int32_t count = r.i32("grid count");
        if (count < 0)
            r.corrupt("a negative grid count (" + std::to_string(count) + ")");
        for (int32_t i = 0; i < count; i++) {
            Grid g;
            r.ctx =
                "grid descriptor " + num((uint64_t)i + 1) + " of " + num((uint64_t)count) + ": ";
            g.unique = r.str("grid name");
            g.name = g.unique.substr(0, g.unique.find('\x1e'));
            g.label = grid_label(g.unique);
            r.ctx = "grid '" + g.label + "' descriptor: ";
            g.type = r.str("grid type");
            // The "_HalfFloat" suffix only sets the flag that the grid's
            // metadata then replaces (g.half, from grid_head).
            const std::string half = "_HalfFloat";
            if (g.type.size() >= half.size() &&
                !g.type.compare(g.type.size() - half.size(), half.size(), half))
                g.type.erase(g.type.size() - half.size());
            g.parent = r.str("instance parent name");
            if (!by_unique.emplace(g.unique, grids.size()).second)
                r.corrupt("a second grid named '" + g.label + "'");
            // GridDescriptor::read: the positions are there (zero) even without offsets.
            const int64_t gp = r.i64("grid position"), bp = r.i64("data position"),
                          ep = r.i64("end position");
            if (offsets) {
                if (ep > 0 && (uint64_t)ep > r.size())
                    throw Rejected{HV_ERR_IO, r.path() + ": truncated: grid '" + g.label +
                                                  "' ends at byte " + num((uint64_t)ep) +
                                                  " but the file has " + num(r.size()) + " bytes"};
                const bool instance = !g.parent.empty();
                if (gp < (int64_t)r.pos || ep < gp || (!instance && (bp < gp || bp > ep)))
                    r.corrupt("grid position " + std::to_string(gp) + ", data position " +
                              std::to_string(bp) + " and end " + std::to_string(ep) +
                              " are out of order or overlap the descriptor (which ends at byte " +
                              num(r.pos) + ")");
                g.grid_pos = (uint64_t)gp;
                g.block_pos = (uint64_t)bp;
                g.end_pos = (uint64_t)ep;
                r.pos = g.grid_pos;
                set_region(g.end_pos, "grid '" + g.label + "'");
                grid_head(g);
                // File::readGridDescriptors seeks to the end of each grid for the next descriptor.
                r.pos = g.end_pos;
                set_region(r.size(), "");
                grids.push_back(g);
            } else {
                // No offsets: OpenVDB reads every grid whole, in order, on open.
                grid_head(g);
                grids.push_back(g);
                if (g.parent.empty())
                    tree(grids.back());
            }
        }
        for (const Grid &g : grids)
            if (!g.parent.empty() && !by_unique.count(g.parent))
                throw Rejected{HV_ERR_IO, r.path() + ": corrupt: grid '" + g.label +
                                              "' is an instance of '" + grid_label(g.parent) +
                                              "', which the file does not have"};
    }

    // io::readCompressedValues for a node of nvals values, active of them
    // active (the value mask read with the topology).
    void values(const Tree &t, uint32_t nvals, uint32_t active)
    {
        const uint64_t at = r.pos;
        const uint8_t code = r.u8("value compression code");
        if (code > NO_MASK_AND_ALL_VALS)
            r.corrupt("unknown value compression code " + num(code) + " at byte " + num(at));
        const uint32_t vsize = t.kind->size;
        if (code == NO_MASK_AND_ONE_INACTIVE_VAL || code == MASK_AND_ONE_INACTIVE_VAL ||
            code == MASK_AND_TWO_INACTIVE_VALS)
            r.skip(vsize, "inactive value", false);
        if (code == MASK_AND_TWO_INACTIVE_VALS)
            r.skip(vsize, "second inactive value", false);
        if (code == MASK_AND_NO_INACTIVE_VALS || code == MASK_AND_ONE_INACTIVE_VAL ||
            code == MASK_AND_TWO_INACTIVE_VALS)
            r.skip(nvals / 8, "selection mask", false);
        const uint64_t count =
            (t.compression & COMP_ACTIVE_MASK) && code != NO_MASK_AND_ALL_VALS ? active : nvals;
        const bool half = t.half && t.kind->half;
        if (half && count == 0)
            return; // io::HalfReader reads nothing at all then
        const uint64_t bytes = count * (half ? t.kind->half : vsize);
        if (!(t.compression & (COMP_BLOSC | COMP_ZIP))) {
            r.skip(bytes, "value block", true);
            return;
        }
        // io::bloscFromStream / unzipFromStream: an int64 size, negative for
        // raw bytes (read into the node's buffer before the size is checked).
        const uint64_t size_at = r.pos;
        const int64_t n = r.i64("value block size");
        if (n <= 0) {
            const uint64_t raw = n == INT64_MIN ? UINT64_MAX : (uint64_t)(-n);
            if (raw != bytes)
                r.corrupt("an uncompressed value block at byte " + num(size_at) + " of " +
                          num(raw) + " bytes where " + num(bytes) + " are expected");
            r.skip(raw, "value block", true);
        } else if (t.compression & COMP_BLOSC) {
            // The header's uncompressed size must be what OpenVDB decompresses
            // into: count values of 2 bytes per component when half.
            blosc_block((uint64_t)n, bytes, false, "value block");
        } else {
            r.skip((uint64_t)n, "value block", true);
        }
    }

    // InternalNode::readTopology (format 222 on): child mask, value mask,
    // the node's values, then its children in mask order.
    void internal(Tree &t, int log2dim)
    {
        const uint32_t nvals = 1u << (3 * log2dim), mbytes = nvals / 8;
        uint64_t child[32768 / 64];
        memcpy(child, r.take(mbytes, "node child mask"), mbytes);
        const unsigned active = popcount(r.take(mbytes, "node value mask"), mbytes);
        values(t, nvals, active);
        for (uint32_t w = 0; w < mbytes / 8; w++)
            for (uint64_t bits = child[w]; bits; bits &= bits - 1) {
                if (log2dim > 4) {
                    internal(t, log2dim - 1);
                } else {
                    const uint8_t *m = r.take(LEAF_MASK_BYTES, "leaf mask");
                    if (t.kind->leaf == LEAF_PLAIN)
                        t.leaf_active.push_back((uint16_t)popcount(m, LEAF_MASK_BYTES));
                    t.leaves++;
                }
            }
    }

    // Root tiles and children (RootNode::readTopology keys its table by the
    // origins as stored). OpenVDB takes each for a node of 4096^3 voxels from
    // its origin: the bounding boxes (CoordBBox::expand(origin, DIM) in
    // evalActiveBoundingBox, createCube) and the voxel loops compute its last
    // voxel as origin + 4095 in int, which must not overflow. It writes them
    // on the 4096-voxel lattice (RootNode::coordToKey), where none can.
    static std::string root_node(const char *what, uint32_t i, uint32_t n, const int32_t o[3])
    {
        return std::string(what) + " " + num(i + 1) + " of " + num(n) + " at (" +
               std::to_string(o[0]) + ", " + std::to_string(o[1]) + ", " + std::to_string(o[2]) +
               ")";
    }
    static bool on_root_lattice(const int32_t o[3])
    {
        return !((o[0] | o[1] | o[2]) & (ROOT_CHILD_DIM - 1));
    }
    void root_node_extent(const char *what, uint32_t i, uint32_t n, const int32_t o[3]) const
    {
        // The extent starts at the origin, an int32: only its end can overflow.
        for (int a = 0; a < 3; a++) {
            const int64_t hi = (int64_t)o[a] + ROOT_CHILD_DIM - 1;
            if (hi > INT32_MAX)
                r.corrupt(root_node(what, i, n, o) +
                          " reaches past the int32 coordinate range: its 4096-voxel extent along " +
                          std::string(1, "xyz"[a]) + " ends at " + std::to_string(hi) +
                          " (at most " + std::to_string(INT32_MAX) + ")");
        }
    }

    // Grid::readTopology then readBuffers (RootNode, InternalNode, LeafNode).
    void tree(Grid &g)
    {
        if (g.tree_checked || !g.parent.empty())
            return;
        const ValueKind *kind = value_kind(g.type);
        if (!kind)
            unsupported("grid '" + g.label + "' is a " + shown(g.type) +
                        " grid; heatvox reads only float, double, int32, int64, vec3 (i, s, d), "
                        "bool and mask grids");
        Tree t{kind, g.half, g.compression, 0, {}};
        r.pos = g.tree_pos;
        if (offsets)
            set_region(g.block_pos, "grid '" + g.label + "' topology");
        else
            set_region(r.size(), "");
        const std::string as_half = g.half && kind->half ? " (values saved as half floats)" : "";
        r.ctx = "grid '" + g.label + "' topology" + as_half + ": ";
        r.i32("buffer count");
        r.skip(kind->size, "background value", false);
        const uint32_t ntiles = r.u32("root tile count"), nchildren = r.u32("root child count");
        const uint64_t tile_bytes = 12 + kind->size + 1; // origin, value, active flag
        r.need((uint64_t)ntiles * tile_bytes, "root tiles", true);
        // Every tile's extent first (the overflow is the worse damage), then
        // the first one off the lattice.
        uint32_t off_lattice = ntiles;
        int32_t off_origin[3] = {0, 0, 0};
        for (uint32_t i = 0; i < ntiles; i++) {
            int32_t o[3];
            memcpy(o, r.take(tile_bytes, "root tile"), 12);
            root_node_extent("root tile", i, ntiles, o);
            if (off_lattice == ntiles && !on_root_lattice(o)) {
                off_lattice = i;
                memcpy(off_origin, o, sizeof o);
            }
        }
        if (off_lattice < ntiles)
            r.corrupt(root_node("root tile", off_lattice, ntiles, off_origin) +
                      " is not on the 4096-voxel lattice");
        int32_t prev[3] = {0, 0, 0};
        for (uint32_t c = 0; c < nchildren; c++) {
            int32_t o[3];
            memcpy(o, r.take(12, "root child origin"), 12);
            root_node_extent("root child", c, nchildren, o);
            if (!on_root_lattice(o))
                r.corrupt(root_node("root child", c, nchildren, o) +
                          " is not on the 4096-voxel lattice");
            // RootNode reads its buffers in the order of its std::map, and
            // OpenVDB writes the children in that order: anything else is damage.
            if (c > 0 && !std::lexicographical_compare(prev, prev + 3, o, o + 3))
                r.corrupt("root children out of order or repeated at child " + num(c + 1));
            memcpy(prev, o, sizeof prev);
            internal(t, 5);
        }
        if (offsets && r.pos != g.block_pos)
            r.corrupt("the topology ends at byte " + num(r.pos) +
                      ", not at the recorded start of the data (byte " + num(g.block_pos) + ")");

        if (offsets)
            set_region(g.end_pos, "grid '" + g.label + "'");
        r.ctx = "grid '" + g.label + "' data" + as_half + ": ";
        switch (kind->leaf) {
        case LEAF_PLAIN:
            // LeafNode::readBuffers on a seekable stream: skip the mask, read
            // the values compressed against the topology's mask.
            for (uint16_t active : t.leaf_active) {
                r.skip(LEAF_MASK_BYTES, "leaf mask", false);
                values(t, LEAF_VALUES, active);
            }
            break;
        case LEAF_BOOL: // value mask, origin, value bits
            r.skip(t.leaves * (64 + 12 + 64), "bool leaves", true);
            break;
        case LEAF_MASK: // value mask, origin
            r.skip(t.leaves * (64 + 12), "mask leaves", true);
            break;
        }
        if (offsets && r.pos != g.end_pos)
            r.corrupt("the data ends at byte " + num(r.pos) +
                      ", not at the grid's recorded end (byte " + num(g.end_pos) + ")");
        set_region(r.size(), "");
        g.tree_checked = true;
    }
};

FileCheck::FileCheck(const std::string &path) : impl_(new Impl(path))
{
    Impl &m = *impl_;
    m.header();
    m.r.ctx = "file metadata: ";
    m.metamap((m.r.size() - m.r.pos) / LEAF_MASK_BYTES);
    m.descriptors();
}

FileCheck::~FileCheck() = default;

void FileCheck::check_tree(const std::string &name)
{
    Impl &m = *impl_;
    // File::findDescriptor matches the name, else "name[N]" by its base name;
    // check every grid either rule could pick, and their instance parents
    // (found again by name, File::readGridByName).
    std::string base = name;
    const size_t open = name.rfind('[');
    if (open != std::string::npos && name.size() > open + 2 && name.back() == ']')
        base = name.substr(0, open);
    std::unordered_set<std::string> parents; // unique names and base names
    for (Grid &g : m.grids) {
        if (g.name != name && g.name != base)
            continue;
        if (g.parent.empty()) {
            m.tree(g);
        } else {
            parents.insert(g.parent);
            parents.insert(g.parent.substr(0, g.parent.find('\x1e')));
        }
    }
    if (!parents.empty())
        for (Grid &p : m.grids)
            if (parents.count(p.unique) || parents.count(p.name))
                m.tree(p);
}

} // namespace hv_vdb_check
