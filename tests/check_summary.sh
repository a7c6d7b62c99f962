#!/bin/sh
# Prints the logs of make check's runs in order, the skipped tests, the
# slowest runs, the variant runs left out ($CHECK_LEFT_OUT) and the closing
# line "check: N passed, M failed, K skipped";
# exits 1 when a run failed, or when its log holds a skip line other than the
# test library's "SKIP: " and "NOT RUN: " at the start of a line. Usage: check_summary.sh RESULTS_DIR RUN...
res=$1
shift
pass=0 fail=0 skip=0 bad=""
skips=$res/skipped.txt
: >"$skips"
for run in "$@"; do
    log=$res/$run.log
    rc=$(cat "$res/$run.rc" 2>/dev/null || echo "?")
    echo "== $run"
    cat "$log" 2>/dev/null
    line=$(grep -E '^[0-9]+%: Checks: ' "$log" 2>/dev/null | tail -n 1)
    if [ -z "$line" ]; then
        fail=$((fail + 1))
        bad="$bad $run(rc=$rc)"
        continue
    fi
    c=$(echo "$line" | sed -E 's/.*Checks: ([0-9]+).*/\1/')
    f=$(echo "$line" | sed -E 's/.*Failures: ([0-9]+), Errors: ([0-9]+).*/\1+\2/')
    f=$(($f))
    s=$(grep -c '^SKIP: ' "$log")
    n=$(grep -c '^NOT RUN: ' "$log")
    # A skip that does not read "SKIP: " at the start of its line is not
    # counted here, so its test would pass without running: the suite fails.
    odd=$(grep -Ei '^[[:space:]]*(skip|skipped|skipping|not run)[[:space:]]*:' "$log" |
        grep -Ev '^(SKIP|NOT RUN): ')
    if [ -n "$odd" ]; then
        echo "$odd" | sed "s|^|  $run: a skip the summary cannot count: |"
        fail=$((fail + 1))
        bad="$bad $run(uncounted skip)"
        continue
    fi
    grep -E '^(SKIP|NOT RUN): ' "$log" | sed "s|^|  $run: |" >>"$skips"
    pass=$((pass + c - f - s))
    fail=$((fail + f))
    skip=$((skip + s + n))
    if [ "$rc" != 0 ] || [ "$f" -ne 0 ]; then bad="$bad $run"; fi
done
echo
echo "slowest runs (wall seconds, side by side):"
for run in "$@"; do
    printf '%s %s\n' "$(cat "$res/$run.ms" 2>/dev/null || echo 0)" "$run"
done | sort -rn | head -n 8 | awk '{ printf "  %-28s %6.1f\n", $2, $1 / 1000 }'
[ ! -s "$skips" ] || { echo "skipped:"; cat "$skips"; }
# Nothing a suite made outside its scratch directory stays: no scratch
# directory of /tmp/hv_* and no mount under one that was not there before.
if [ -f "$res/tmp.before" ]; then
    { ls -d /tmp/hv_* 2>/dev/null; grep -o ' /tmp/hv_[^ ]*' /proc/mounts; } | sort >"$res/tmp.after"
    left=$(comm -13 "$res/tmp.before" "$res/tmp.after")
    if [ -n "$left" ]; then
        echo "left behind by the suites:"
        echo "$left" | sed 's/^ */  /'
        fail=$((fail + 1))
        bad="$bad (leftovers)"
    fi
fi
[ -z "$bad" ] || echo "failing suites:$bad"
# Variant runs that make check did not list here (CHECK_LEFT_OUT, from
# mk/tests.mk: "RUNS (why);" each), counted neither passed nor skipped.
left=${CHECK_LEFT_OUT:-}
[ -z "$left" ] || echo "variants left out: ${left%;}"
echo "check: $pass passed, $fail failed, $skip skipped"
[ -z "$bad" ]
