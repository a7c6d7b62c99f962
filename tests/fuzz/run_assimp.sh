#!/bin/sh
# Runs the assimp fuzz target for SECONDS, going on past the inputs whose
# fault lies in assimp's library (Debian's libassimp 5.2: tests/fuzz/README.md).
# The target runs as the others do and stops at the first input that fails.
# That input is replayed so that its report has a stack: libFuzzer's RSS
# limit prints none, and a single request of 20 GB is stopped by it (ASan
# poisons the block's shadow before the malloc limit's hook runs), so the
# replay refuses requests over 2 GB before allocating them, and
# FZ_HEAP_LIMIT_MB stops a heap that grows by small blocks (fuzz_assimp.c).
# An input whose report reaches libassimp before any of heatvox's code (a
# segfault inside a reader, an allocation of what the file declares, a leak
# on a failed read), or that fails no more when replayed alone, moves to
# LIBDIR with a line on stdout (its name, the report, the extension it was
# read as), and the target starts again for the time left. Any other input
# stays in CRASHDIR and ends the run with exit code 1, as a crash of any
# target does.
#
# usage: tests/fuzz/run_assimp.sh FUZZ_BINARY SECONDS CRASHDIR LIBDIR LOG [LIBFUZZER ARGS...]
set -u
bin=$1 seconds=$2 dir=$3 lib=$4 log=$5
shift 5
exts=".gltf .glb .fbx .3mf .dae .x" # tests/fuzz/fuzz_assimp.h
end=$(($(date +%s) + seconds))
: >"$log"
mkdir -p "$dir"
while :; do
    left=$((end - $(date +%s)))
    [ "$left" -gt 0 ] || exit 0
    before=$(ls "$dir" | wc -l)
    timeout -k 10 $((left + 120)) "$bin" -max_total_time="$left" -artifact_prefix="$dir/" "$@" >>"$log" 2>&1
    rc=$?
    if [ $rc -eq 124 ] || [ $rc -eq 137 ]; then
        echo "  the target ran 120 s past its time and was stopped (log: $log)" >&2
        exit 1
    fi
    [ "$(ls "$dir" | wc -l)" -gt "$before" ] || exit $rc # time up, or a failure with no input kept
    for f in "$dir"/*; do
        [ -f "$f" ] || continue
        out=$(ASAN_OPTIONS="${ASAN_OPTIONS:+$ASAN_OPTIONS:}max_allocation_size_mb=2048" \
            FZ_HEAP_LIMIT_MB=1024 timeout -k 10 120 "$bin" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=2048 "$f" 2>&1)
        replay=$?
        if [ $replay -eq 124 ] || [ $replay -eq 137 ]; then
            echo "  kept $(basename "$f"): its replay ran past 120 s" >&2
            exit 1
        fi
        # the first stack frame in libassimp or in heatvox's own sources,
        # the heap watch's own frame aside
        first=$(printf '%s\n' "$out" | grep -E '^ +#[0-9]+ ' | grep -v fz_heap_watch |
            grep -m 1 -E 'libassimp\.so|/(src|tests/fuzz)/|\<hv_' || true)
        kind=$(printf '%s\n' "$out" | grep -m 1 -oE 'SEGV|out-of-memory|allocation-size-too-big|timeout|detected memory leaks|[a-z-]+-overflow|use-after-free|deadly signal|runtime error' || true)
        case $first in
        *libassimp.so*) why="$kind in libassimp" ;;
        *)
            if [ -n "$kind" ]; then
                echo "  kept $(basename "$f"): $kind, first frame: ${first:-none}" >&2
                exit 1
            fi
            why="does not fail alone"
            ;;
        esac
        mkdir -p "$lib"
        mv "$f" "$lib/"
        sel=$(od -An -tu1 -N1 "$lib/$(basename "$f")" | tr -d ' ')
        ext=$(echo $exts | cut -d' ' -f$((sel % 6 + 1)))
        echo "  $(basename "$f"): $why (read as $ext)"
    done
done
