/* A render client: hello, the scene, ready; then tiles until rank 0 says quit, each rendered with
 * the device's threads and sent back packed (wire.c). */
#include <errno.h>
#include <math.h>
#include <mpi.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <unistd.h>

#include "cli.h"
#include "mpi_render.h"

int mpir_client_run(const mpir_options *o, int rank, bool *no_finalize) {
    double idle_s = 4.0 * o->timeout_s; /* silence from rank 0 after which a client gives up */
    if (mpir_test_hook("STALL", rank)) {
        for (;;) mpir_sleep_us(1000000); /* a client that never answers: rank 0 must time out */
    }
    hello_msg hello = {.magic = MPIR_MAGIC, .protocol = MPIR_PROTOCOL,
                       .version = {RP_VERSION_MAJOR, RP_VERSION_MINOR, RP_VERSION_PATCH},
                       .desc_bytes = (uint32_t)sizeof(rp_render_desc), .pid = (int32_t)getpid()};
    long proto = mpir_test_hook("PROTOCOL", rank);
    if (proto) hello.protocol = (uint32_t)proto;
    gethostname(hello.host, sizeof hello.host - 1);
    if (!mpir_send_until(&hello, sizeof hello, 0, TAG_HELLO, MPI_Wtime() + idle_s)) return CLI_EXIT_FAILURE;

    mpir_scene rs;
    memset(&rs, 0, sizeof rs);
    ready_msg ready = {.ok = 1};
    bool loaded;
    if (o->bcast) {
        uint64_t size = 0;
        uint8_t *buf = NULL;
        loaded = mpir_bcast_until(&size, sizeof size, MPI_Wtime() + idle_s) && (buf = malloc(size ? size : 1)) &&
                 mpir_bcast_until(buf, size, MPI_Wtime() + idle_s);
        if (!loaded) snprintf(ready.err, sizeof ready.err, "did not receive the broadcast scene");
        else loaded = wire_scene_unpack(buf, size, &rs.data, ready.err, sizeof ready.err);
        free(buf);
    } else {
        loaded = mpir_scene_load(&rs, o->scene, ready.err, sizeof ready.err);
    }
    if (loaded && mpir_scene_build(&rs, o, o->threads, ready.err, sizeof ready.err)) {
        ready.threads = rp_device_thread_count(rs.device);
        ready.triangles = rs.data.triangle_count;
    } else {
        ready.ok = 0;
    }
    int status = CLI_EXIT_FAILURE;
    mpir_tile_worker w = {0};
    if (!mpir_send_until(&ready, sizeof ready, 0, TAG_READY, MPI_Wtime() + idle_s)) goto done;
    if (!ready.ok) {
        /* Rank 0 reports the error and aborts the job; leaving first could let mpirun kill rank 0
         * before it has said why. */
        double until = MPI_Wtime() + idle_s;
        while (MPI_Wtime() < until) mpir_sleep_us(10000);
        goto done;
    }

    long kill_after = mpir_test_hook("KILL", rank), hang_after = mpir_test_hook("HANG", rank);
    long rendered = 0;
    uint8_t *msg = NULL;
    size_t msg_cap = 0;
    for (;;) {
        MPI_Status st;
        if (!mpir_probe_until(0, TAG_JOB, MPI_Wtime() + idle_s, &st)) {
            fprintf(stderr, "raypack render: rank %d heard nothing from rank 0 for %.1f s; giving up\n", rank, idle_s);
            break;
        }
        job_msg job;
        MPI_Recv(&job, (int)sizeof job, MPI_BYTE, 0, TAG_JOB, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        if (job.kind == JOB_QUIT) {
            status = CLI_EXIT_OK;
            *no_finalize = job.tile != 0;
            break;
        }
        /* kill -9 in the middle of a frame, holding this tile and the one queued behind it */
        if (kill_after && rendered == kill_after) raise(SIGKILL);
        /* ... or hang there, alive but silent */
        if (hang_after && rendered == hang_after)
            for (;;) mpir_sleep_us(1000000);
        rp_render_stats rst;
        result_msg res = {.kind = RESULT_TILE, .frame = job.frame, .tile = job.tile,
                          .region = {job.region[0], job.region[1], job.region[2], job.region[3]}};
        size_t payload = 0;
        const void *body = NULL;
        char err[256];
        if (mpir_tile_render(&w, rs.scene, &job, &rst)) {
            double c0 = mpir_cpu_ms();
            res.floats = (uint64_t)(job.region[2] - job.region[0]) * (uint64_t)(job.region[3] - job.region[1]) * 3;
            payload = wire_tile_pack(w.codec, w.tile, (size_t)res.floats, job.raw_planes, w.scratch, w.packed,
                                     w.packed_cap);
            body = w.packed;
            res.render_ms = rst.render_ms;
            res.render_cpu_ms = w.render_cpu_ms;
            /* the copy out of the frame is in render_cpu_ms's complement: count it with the packing */
            res.pack_cpu_ms = mpir_cpu_ms() - c0;
            for (int k = 0; k < RP_RAY_KIND_COUNT; k++) res.rays += rst.rays[k];
        }
        if (!payload) {
            res.kind = RESULT_ERROR;
            snprintf(err, sizeof err, "rank %d could not render tile %u of frame %u (out of memory?)", rank, job.tile,
                     job.frame);
            body = err;
            payload = strlen(err) + 1;
        }
        if (sizeof res + payload > msg_cap) {
            free(msg);
            msg_cap = sizeof res + payload;
            msg = malloc(msg_cap);
            if (!msg) break;
        }
        memcpy(msg, &res, sizeof res);
        memcpy(msg + sizeof res, body, payload);
        if (!mpir_send_until(msg, sizeof res + payload, 0, TAG_RESULT, MPI_Wtime() + idle_s)) {
            fprintf(stderr, "raypack render: rank %d could not send a tile to rank 0 within %.1f s; giving up\n", rank,
                    idle_s);
            break;
        }
        rendered++;
    }
    free(msg);
done:
    mpir_tile_worker_free(&w);
    mpir_scene_free(&rs);
    return status;
}
