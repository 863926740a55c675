/* A render client: hello, the scene, ready; then tiles until rank 0 says quit, each rendered with
 * the device's threads and sent back packed (wire.c). */
#include <errno.h>
#include <math.h>
#include <mpi.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <unistd.h>

#include "cli.h"
#include "mpi_render.h"

/* Sends the queued frames; false (with a message) when rank 0 is gone or silent. */
static bool send_all(mpir_conn *c, int rank, double idle_s, const char *what) {
    int rc = mpir_conn_send_idle(c, idle_s);
    if (rc > 0) return true;
    if (rc < 0) fprintf(stderr, "raypack render: rank %d lost rank 0 sending %s (%s); giving up\n", rank, what, c->err);
    else fprintf(stderr, "raypack render: rank %d could not send %s to rank 0 within %.1f s; giving up\n", rank, what, idle_s);
    return false;
}

int mpir_client_run(const mpir_options *o, int rank, bool *no_finalize) {
    double idle_s = 4.0 * o->timeout_s; /* silence from rank 0 after which a client gives up */
    if (mpir_test_hook("STALL", rank)) {
        for (;;) mpir_sleep_us(1000000); /* a client that never answers: rank 0 must time out */
    }
    if (mpir_test_hook("PROTOCOL1", rank)) {
        /* a client of protocol 1, which said hello over MPI: rank 0 must name it, not wait for it */
        hello_msg old = {.magic = MPIR_MAGIC, .protocol = 1, .version = {RP_VERSION_MAJOR, RP_VERSION_MINOR, 0},
                         .pid = (int32_t)getpid()};
        gethostname(old.host, sizeof old.host - 1);
        MPI_Request r;
        MPI_Isend(&old, (int)offsetof(hello_msg, rank), MPI_BYTE, 0, TAG_HELLO, MPI_COMM_WORLD, &r);
        for (;;) mpir_sleep_us(1000000);
    }
    /* Rank 0's address, the one MPI message; then everything goes over our connection. */
    rendezvous_msg rv;
    memset(&rv, 0, sizeof rv);
    MPI_Request req;
    char err[256];
    if (MPI_Irecv(&rv, (int)sizeof rv, MPI_BYTE, 0, TAG_RENDEZVOUS, MPI_COMM_WORLD, &req) != MPI_SUCCESS ||
        !mpir_wait_until(&req, mpir_now_s() + idle_s)) {
        fprintf(stderr, "raypack render: rank %d heard nothing from rank 0 for %.1f s; giving up\n", rank, idle_s);
        return CLI_EXIT_FAILURE;
    }
    rv.host[sizeof rv.host - 1] = '\0';
    int fd = rv.magic == MPIR_MAGIC ? mpir_connect(&rv, mpir_now_s() + idle_s, err, sizeof err) : -1;
    if (fd < 0) {
        fprintf(stderr, "raypack render: rank %d: %s; giving up\n", rank,
                rv.magic == MPIR_MAGIC ? err : "rank 0 is not a raypack render server");
        return CLI_EXIT_FAILURE;
    }
    mpir_conn conn;
    mpir_conn_init(&conn, fd, (uint64_t)1 << 40);
    hello_msg hello = {.magic = MPIR_MAGIC, .protocol = MPIR_PROTOCOL,
                       .version = {RP_VERSION_MAJOR, RP_VERSION_MINOR, RP_VERSION_PATCH},
                       .desc_bytes = (uint32_t)sizeof(rp_render_desc), .pid = (int32_t)getpid(), .rank = rank,
                       .token = rv.token};
    long proto = mpir_test_hook("PROTOCOL", rank);
    if (proto) hello.protocol = (uint32_t)proto;
    gethostname(hello.host, sizeof hello.host - 1);
    int status = CLI_EXIT_FAILURE;
    mpir_scene rs;
    memset(&rs, 0, sizeof rs);
    mpir_tile_worker w = {0};
    if (!mpir_conn_queue(&conn, MSG_HELLO, &hello, sizeof hello, NULL, 0) || !send_all(&conn, rank, idle_s, "its hello"))
        goto done;

    /* the test of a client's death during start-up (with --mpi-bcast: while its scene is sent) */
    if (mpir_test_hook("DIE_AT_START", rank)) raise(SIGKILL);
    ready_msg ready = {.ok = 1};
    bool loaded;
    if (o->bcast) {
        /* rank 0 loads the scene first; a dead rank 0 is an end of stream at once, so this bound
         * is only for one that hangs */
        int rc = mpir_conn_recv_idle(&conn, idle_s > 120.0 ? idle_s : 120.0);
        loaded = rc > 0 && conn.hdr.type == MSG_SCENE;
        if (!loaded) snprintf(ready.err, sizeof ready.err, "did not receive the broadcast scene (%s)", rc < 0 ? conn.err : "time-out");
        else loaded = wire_scene_unpack(conn.in, (size_t)conn.hdr.bytes, &rs.data, ready.err, sizeof ready.err);
        mpir_conn_next(&conn);
        /* the scene's buffer is not needed again: a frame of tiles is small */
        free(conn.in);
        conn.in = NULL;
        conn.in_cap = 0;
    } else {
        loaded = mpir_scene_load(&rs, o, false, ready.err, sizeof ready.err);
    }
    if (loaded && mpir_scene_build(&rs, o, o->threads, ready.err, sizeof ready.err)) {
        ready.threads = rp_device_thread_count(rs.device);
        ready.triangles = rs.data.triangle_count;
    } else {
        ready.ok = 0;
    }
    if (!mpir_conn_queue(&conn, MSG_READY, &ready, sizeof ready, NULL, 0) || !send_all(&conn, rank, idle_s, "its ready"))
        goto done;
    if (!ready.ok) {
        /* Rank 0 reports the error and aborts the job; leaving first could let mpirun kill rank 0
         * before it has said why. Wait for it to close the connection. */
        mpir_conn_recv_idle(&conn, idle_s);
        goto done;
    }

    long kill_after = mpir_test_hook("KILL", rank), hang_after = mpir_test_hook("HANG", rank);
    long rendered = 0;
    int frame = -1;
    for (;;) {
        int rc = mpir_conn_recv_idle(&conn, idle_s);
        if (rc <= 0) {
            if (rc < 0) fprintf(stderr, "raypack render: rank %d lost rank 0 (%s); giving up\n", rank, conn.err);
            else fprintf(stderr, "raypack render: rank %d heard nothing from rank 0 for %.1f s; giving up\n", rank, idle_s);
            break;
        }
        job_msg job;
        if (conn.hdr.type != MSG_JOB || conn.hdr.bytes != sizeof job) {
            fprintf(stderr, "raypack render: rank %d got a frame of type %u from rank 0, not a job; giving up\n", rank,
                    conn.hdr.type);
            break;
        }
        memcpy(&job, conn.in, sizeof job);
        mpir_conn_next(&conn);
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
        result_msg res = {.kind = RESULT_TILE, .frame = job.frame, .tile = job.tile,
                          .region = {job.region[0], job.region[1], job.region[2], job.region[3]}};
        size_t payload = 0;
        const void *body = NULL;
        char jerr[512] = "";
        rp_render_stats rst;
        if ((int)job.frame != frame && job.animated && !mpir_scene_frame(&rs, job.anim_time, jerr, sizeof jerr)) {
            /* reported below as the tile's error */
        } else if (mpir_tile_render(&w, rs.scene, &job, &rst)) {
            frame = (int)job.frame;
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
        char text[700];
        if (!payload) {
            res.kind = RESULT_ERROR;
            snprintf(text, sizeof text, "rank %d could not render tile %u of frame %u: %s", rank, job.tile, job.frame,
                     jerr[0] ? jerr : "out of memory?");
            body = text;
            payload = strlen(text);
        }
        if (!mpir_conn_queue(&conn, MSG_RESULT, &res, sizeof res, body, payload) ||
            !send_all(&conn, rank, idle_s, "a tile"))
            break;
        rendered++;
    }
done:
    mpir_conn_close(&conn);
    mpir_tile_worker_free(&w);
    mpir_scene_free(&rs);
    return status;
}
