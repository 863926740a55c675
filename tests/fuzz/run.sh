#!/usr/bin/env bash
# Runs every libFuzzer harness of the fuzz build for FUZZ_SECONDS each (or FUZZ_RUNS inputs from
# seed FUZZ_SEED, as CI does: the same inputs every run) (JOBS at a time), from a
# scratch copy of its seed corpus (so the repository's seeds stay small), after replaying every
# crash reproducer in tests/fuzz/crashes/NAME. Prints executions per second and in total per parser;
# exits non-zero if any harness crashed, leaked, hung (-timeout) or went past -rss_limit_mb. A
# crash's input is left in build/fuzz/artifacts/NAME/: copy it to tests/fuzz/crashes/NAME/ with
# the fix, so every later run (and CTest's replay) checks it. FUZZ_TIMEOUT (seconds, default 10) is
# libFuzzer's per-input hang limit: raise it for long runs under nice beside other work, where a
# starved process otherwise reports a hang that replays in a millisecond.
set -euo pipefail
cd "$(dirname "$0")/../.."
SECONDS_EACH=${FUZZ_SECONDS:-60}
JOBS=${FUZZ_JOBS:-2}
BIN=build/fuzz/tests/fuzz
OUT=build/fuzz/runs
# vdb (OpenVDB) only when named: io_vdb.cpp checks the metadata's declared lengths against the file's
# size (OpenVDB 10 allocated them first: 25 s and 3 GB for a corrupt 10 kB file), but not the trees'
# compressed blocks, whose absurd sizes fail inside OpenVDB's new[]; fuzzing it needs the limits below
NAMES=${FUZZ_NAMES:-"obj mtl ply nff aff tar texture gltf"}
mkdir -p "$OUT"
export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1

run_one() {
    local name=$1 work=$OUT/corpus_$1 art=build/fuzz/artifacts/$1/
    mkdir -p "$work" "$art"
    # glTF goes through assimp (uninstrumented C++, about 40 inputs/s against 20000 for the
    # others): FUZZ_RUNS_GLTF inputs (default FUZZ_RUNS/400); ASan keeps the memory it frees
    # instead of returning it to the kernel and faulting it in again (5x faster), and unwinds
    # malloc's stacks the slow way (8x slower), which the suppression of assimp 5.2's documented
    # leak (lsan_gltf.supp) needs to see the frame it names
    local runs=${FUZZ_RUNS:-} asan=$ASAN_OPTIONS lsan=${LSAN_OPTIONS:-}
    if [ "$name" = gltf ]; then
        [ -n "$runs" ] && runs=${FUZZ_RUNS_GLTF:-$((runs / 400))}
        asan=$asan:allocator_release_to_os_interval_ms=100000:quarantine_size_mb=16:fast_unwind_on_malloc=0
        lsan=suppressions=$PWD/tests/fuzz/lsan_gltf.supp
    fi
    # .vdb goes through OpenVDB (uninstrumented C++ too, and a file write per input), with its leak
    # when a truncated file makes it throw suppressed (tests/lsan_openvdb.supp) and its huge
    # metadata allocations allowed (see NAMES)
    local limits=(-timeout="${FUZZ_TIMEOUT:-10}" -rss_limit_mb=1024 -malloc_limit_mb=512)
    if [ "$name" = vdb ]; then
        [ -n "$runs" ] && runs=${FUZZ_RUNS_VDB:-$((runs / 400))}
        lsan=suppressions=$PWD/tests/lsan_openvdb.supp
        limits=(-timeout=60 -rss_limit_mb=6000 -malloc_limit_mb=4500)
    fi
    if [ -d "tests/fuzz/crashes/$name" ] && [ -n "$(ls -A "tests/fuzz/crashes/$name")" ]; then
        ASAN_OPTIONS=$asan LSAN_OPTIONS=$lsan "$BIN/fuzz_$name" -runs=0 "tests/fuzz/crashes/$name"/* >"$OUT/$name.replay.log" 2>&1 ||
            { echo "$name: a past crash reproducer fails again (see $OUT/$name.replay.log)"; return 1; }
    fi
    # FUZZ_RUNS (CI): a fixed number of inputs from a fixed seed, so the run is the same every time
    # and CI fails only when the code changes, not when a random search gets lucky; else by time
    local budget=(-max_total_time="$SECONDS_EACH")
    [ -n "$runs" ] && budget=(-runs="$runs" -seed="${FUZZ_SEED:-1}")
    ASAN_OPTIONS=$asan LSAN_OPTIONS=$lsan "$BIN/fuzz_$name" "${budget[@]}" "${limits[@]}" \
        -max_len=16384 -print_final_stats=1 -artifact_prefix="$art" "$work" "tests/fuzz/corpus/$name" \
        >"$OUT/$name.log" 2>&1
}
export -f run_one
export BIN OUT SECONDS_EACH FUZZ_RUNS FUZZ_SEED FUZZ_RUNS_GLTF FUZZ_RUNS_VDB FUZZ_TIMEOUT

status=0
printf '%s\n' $NAMES | xargs -P "$JOBS" -I{} bash -c 'run_one {}' || status=1
printf '%-8s %12s %12s %8s\n' parser executions "exec/s" corpus
for name in $NAMES; do
    log=$OUT/$name.log
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    files=$(ls "$OUT/corpus_$name" | wc -l)
    printf '%-8s %12s %12s %8s\n' "$name" "${execs:-?}" "${rate:-?}" "$files"
    if grep -qE "ERROR: (AddressSanitizer|LeakSanitizer|libFuzzer)|runtime error:|SUMMARY: " "$log"; then
        echo "$name: FAILED (see $log; input in build/fuzz/artifacts/$name/)"
        grep -m3 -E "ERROR:|runtime error:|SUMMARY:" "$log" || true
        status=1
    fi
done
exit $status
