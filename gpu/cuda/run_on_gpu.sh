#!/bin/sh
# Builds raypack with the CUDA backend, runs the CUDA test and the benchmarks on a GPU machine and
# writes every result into one folder. Well under 15 minutes on a 16-core H200 machine.
#   gpu/cuda/run_on_gpu.sh [RESULTS_DIR] [SCENES_DIR]
# RESULTS_DIR defaults to $OUT, else ./gpu_results; SCENES_DIR to $RP_SCENES, else ../shared/scenes.
set -u
cd "$(dirname "$0")/../.."
RES=${1:-${OUT:-gpu_results}}
SCENES=${2:-${RP_SCENES:-$(pwd)/../shared/scenes}}
mkdir -p "$RES"
RES=$(cd "$RES" && pwd)
log() { echo "== $*" | tee -a "$RES/summary.txt"; }
log "raypack CUDA run $(date -u +%FT%TZ) on $(hostname)"
nvidia-smi > "$RES/nvidia-smi.txt" 2>&1 || log "nvidia-smi failed"
/usr/local/cuda/bin/nvcc --version > "$RES/nvcc.txt" 2>&1
B=build/gpu
log "configure"
timeout 300 cmake -S . -B $B -DCMAKE_BUILD_TYPE=Release -DRP_WERROR=ON -DRP_SCENES_DIR="$SCENES" \
    > "$RES/configure.txt" 2>&1 || { log "configure failed (see configure.txt)"; exit 1; }
log "build"
timeout 600 cmake --build $B -j"$(nproc)" --target test_cuda_grid test_grid test_stream raypack_cli \
    > "$RES/build.txt" 2>&1 || { log "build failed (see build.txt)"; exit 1; }
export RP_SCENES="$SCENES"
log "test_cuda_grid"
timeout 300 $B/gpu/cuda/test_cuda_grid > "$RES/test_cuda_grid.txt" 2>&1; echo "exit $?" >> "$RES/test_cuda_grid.txt"
tail -3 "$RES/test_cuda_grid.txt" | tee -a "$RES/summary.txt"
log "test_cuda_grid --bench"
timeout 300 $B/gpu/cuda/test_cuda_grid --bench > "$RES/bench_cuda_grid.txt" 2>&1
tail -4 "$RES/bench_cuda_grid.txt" | tee -a "$RES/summary.txt"
log "CPU tests (grid, stream)"
timeout 300 $B/tests/test_grid > "$RES/test_grid.txt" 2>&1; tail -1 "$RES/test_grid.txt" | tee -a "$RES/summary.txt"
timeout 300 $B/tests/test_stream > "$RES/test_stream.txt" 2>&1; tail -1 "$RES/test_stream.txt" | tee -a "$RES/summary.txt"
log "bench --stream --purcell (bunny)"
timeout 300 $B/raypack bench "$SCENES/stanford_bunny_bun_zipper.ply.gz" --stream --purcell > "$RES/bench_stream_bunny.txt" 2>&1
cat "$RES/bench_stream_bunny.txt" >> "$RES/summary.txt"
log "done $(date -u +%FT%TZ)"
