#!/bin/sh
# The GPU checks and benchmark of gpu/cuda, in two steps: the GPU machine has the CUDA driver but
# not the Debian libraries behind raypack's loaders (assimp, libarchive, OpenEXR, ...), and not the
# shared scenes. So the programs are built here, linked against the core and the static CUDA runtime
# alone, and the scenes travel as raw meshes (gpu_mesh_dump, cuda_mesh.h).
#
#   gpu/cuda/run_on_gpu.sh prepare [DIR]          here: builds test_cuda_bvh and writes DIR (default
#                                                 .gpu): the program and the meshes of the shared scenes
#   gpu/cuda/run_on_gpu.sh run [DIR] [RESULTS]    on the GPU machine: nvidia-smi, then test_cuda_bvh on
#                                                 every mesh (checks against the CPU, then Mrays/s), all
#                                                 output into RESULTS (default $OUT, else gpu_results)
#
# With the session's device tool: prepare, then run `sh gpu/cuda/run_on_gpu.sh run .gpu $OUT` with
# .gpu carried (add it to .git/info/exclude). It takes about a minute there.
set -u
cd "$(dirname "$0")/../.."
step=${1:-}
DIR=${2:-.gpu}
case "$step" in
prepare)
    SCENES=${RP_SCENES:-$(pwd)/../shared/scenes}
    B=build/release
    cmake --preset release > /dev/null && cmake --build --preset release -j "$(nproc)" --target test_cuda_bvh gpu_mesh_dump || exit 1
    mkdir -p "$DIR"
    cp $B/gpu/cuda/test_cuda_bvh "$DIR/"
    dump() { $B/gpu/cuda/gpu_mesh_dump "$SCENES/$1" "$DIR/$2.rpmesh" ${3:-} || exit 1; }
    # the conference from inside (issue 27's goals), and the other scenes from their own cameras
    dump conference_geom.obj.gz conference "--eye 1500,350,500 --look 0,150,-400 --up 0,1,0 --fov 60"
    dump stanford_bunny_bun_zipper.ply.gz bunny
    dump dabrovic_sponza.obj.gz sponza "--eye -14,3,0 --look 10,5,0 --up 0,1,0 --fov 70"
    dump bart_kitchen.tar.gz kitchen
    dump bart_museum5.tar.gz museum
    dump spd_rings_s5.nff.gz rings
    du -sh "$DIR"
    ;;
run)
    RES=${3:-${OUT:-gpu_results}}
    mkdir -p "$RES"
    {
        echo "== raypack GPU run $(date -u +%FT%TZ) on $(hostname)"
        nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm,memory.total --format=csv 2>&1
        echo "== checks and speed, 2048x2048, best of 10"
        "$DIR/test_cuda_bvh" --size 2048x2048 --repeats 10 "$DIR"/conference.rpmesh "$DIR"/bunny.rpmesh \
            "$DIR"/sponza.rpmesh "$DIR"/kitchen.rpmesh "$DIR"/museum.rpmesh "$DIR"/rings.rpmesh
        echo "exit $?"
        echo "== CTest's size, 512x512"
        "$DIR/test_cuda_bvh" --size 512x512 --repeats 3 "$DIR"/bunny.rpmesh "$DIR"/conference.rpmesh
        echo "exit $?"
        echo "== done $(date -u +%FT%TZ)"
    } > "$RES/gpu_run.txt" 2>&1
    cat "$RES/gpu_run.txt"
    ;;
*)
    echo "usage: gpu/cuda/run_on_gpu.sh prepare [DIR] | run [DIR] [RESULTS]" >&2
    exit 2
    ;;
esac
