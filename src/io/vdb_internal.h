// Private to the OpenVDB shim (vdb_write.cpp, vdb_read.cpp): what its files
// share. Every entry point of include/heatvox/vdb.h runs its body inside
// guarded(), which turns any exception into an hv_status with a message;
// nothing escapes into C. The shim keeps default symbol visibility (see the
// Makefile: OpenVDB's templates hidden in a program crash openvdb::initialize()).
#ifndef HV_IO_VDB_INTERNAL_H
#define HV_IO_VDB_INTERNAL_H

#include "heatvox/vdb.h"

extern "C" {
#include "core/error.h"
}

#include <openvdb/openvdb.h>
#include <tbb/task_arena.h>

#include <mutex>
#include <new>
#include <string>

namespace hv_vdb_shim
{

// Grid metadata of heatvox's writer: the index box of the dense block.
inline constexpr const char *BLOCK_MIN = "heatvox_block_min";
inline constexpr const char *BLOCK_MAX = "heatvox_block_max";

// An error detected inside the shim, carried to the C boundary.
struct Fail {
    hv_status st;
    std::string msg;
};

[[noreturn]] inline void fail(hv_status st, const std::string &msg) { throw Fail{st, msg}; }

// `where` names the file or operation, so that OpenVDB's own messages (which
// often omit it) still say which input failed. The body's parallel work
// (TBB's, OpenVDB's own included) runs on hv_get_threads() threads, as the
// library's OpenMP loops do.
template <class F> hv_status guarded(const char *where, F &&body)
{
    try {
        const int threads = hv_get_threads();
        tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
        return arena.execute([&] { return body(); });
    } catch (const Fail &e) {
        return hv__error(e.st, "%s", e.msg.c_str());
    } catch (const openvdb::IoError &e) {
        return hv__error(HV_ERR_IO, "%s: %s", where, e.what());
    } catch (const openvdb::Exception &e) {
        return hv__error(HV_ERR_BACKEND, "%s: OpenVDB: %s", where, e.what());
    } catch (const std::bad_alloc &) {
        return hv__error(HV_ERR_NOMEM, "%s: out of memory", where);
    } catch (const std::exception &e) {
        return hv__error(HV_ERR_BACKEND, "%s: %s", where, e.what());
    } catch (...) {
        return hv__error(HV_ERR_INTERNAL, "%s: unknown exception", where);
    }
}

inline void init_vdb()
{
    static std::once_flag init_flag;
    std::call_once(init_flag, [] { openvdb::initialize(); });
}

} // namespace hv_vdb_shim

#endif
