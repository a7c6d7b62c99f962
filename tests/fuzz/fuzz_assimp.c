/* libFuzzer target: hv_mesh_read on the formats read through assimp. The
 * first byte picks the extension, the rest is the file: one target and one
 * corpus for them all keep the fuzz stage's time. A mesh that loads also
 * goes through the report and the bounds.
 *
 * With FZ_HEAP_LIMIT_MB set (run_assimp.sh sets it when it replays an
 * input), a malloc hook stops the process, with the stack of the allocation,
 * once the live heap passes that many MB. libFuzzer's own -rss_limit_mb
 * report has no stack, so it cannot tell whether assimp's import or
 * heatvox's code after it took the memory; this one can. */
#include "fuzz_assimp.h"
#include "fuzz_common.h"

#include <sanitizer/allocator_interface.h>
#include <sanitizer/common_interface_defs.h>

static size_t heap_limit;

static void fz_heap_watch(const volatile void *p, size_t size)
{
    static int stopping;
    (void)p;
    (void)size;
    if (stopping || __sanitizer_get_current_allocated_bytes() <= heap_limit)
        return;
    stopping = 1;
    fprintf(stderr,
            "==%ld== ERROR: fz: out-of-memory (the live heap passed FZ_HEAP_LIMIT_MB=%zu); "
            "the allocation that passed it:\n",
            (long)getpid(), heap_limit >> 20);
    __sanitizer_print_stack_trace();
    fflush(stderr);
    _exit(1);
}

static void fz_heap_unwatch(const volatile void *p) { (void)p; }

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    const char *mb = getenv("FZ_HEAP_LIMIT_MB");
    if (mb && atol(mb) > 0) {
        heap_limit = (size_t)atol(mb) << 20;
        /* both hooks, or the sanitizer installs neither */
        __sanitizer_install_malloc_and_free_hooks(fz_heap_watch, fz_heap_unwatch);
    }
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1)
        return 0;
    const char *path = fz_file(data + 1, size - 1, fz_assimp_ext(data[0]));
    if (!path)
        return 0;
    hv_mesh *m = NULL;
    if (hv_mesh_read(path, &m) == HV_OK) {
        hv_mesh_report r;
        double lo[3], hi[3];
        hv_mesh_report_compute(m, &r);
        hv_mesh_bounds(m, lo, hi);
    }
    hv_mesh_destroy(&m);
    fz_done(path);
    return 0;
}
