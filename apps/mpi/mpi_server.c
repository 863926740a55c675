/* The display server: the handshake, the tiles of every frame handed out with one queued ahead
 * per client, lost clients' tiles re-issued, the images written, the report. */
#include <errno.h>
#include <math.h>
#include <mpi.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <unistd.h>

#include "cli.h"
#include "mpi_render.h"

enum { QUEUE_AHEAD = 2 }; /* tiles a client holds: the one it renders and the one queued behind it */

typedef struct client {
    int rank;
    bool alive;                    /* connected and ready, not lost */
    bool ready;
    hello_msg hello;
    int threads;
    mpir_conn conn;                /* its TCP connection (mpi_net.c); fd -1 once closed */
    int held;                      /* tiles issued and not returned */
    uint32_t held_tile[QUEUE_AHEAD];
    double last_heard;             /* mpir_now_s of its last result, or of an issue to it while it held none */
    uint64_t in0, out0;            /* conn's byte counts when this frame began */
    uint64_t tiles, bytes_in, bytes_out;          /* this frame */
    uint64_t tiles_all, bytes_in_all, bytes_out_all;
    double tile_ms_all;
} client;

enum { TILE_PENDING = 0, TILE_ISSUED = 1, TILE_DONE = 2 };

typedef struct server {
    const mpir_options *o;
    int size;
    client *clients;     /* ranks 1..size-1 at [rank - 1] */
    int width, height;
    int tiles_x, tiles_y, tiles;
    uint8_t *state;      /* per tile */
    int *owner;          /* the client that rendered each tile last frame (affinity), -1 none */
    int done;
    float *image;
    uint8_t *scratch;
    wire_codec *codec;
    float *tile_px;      /* one tile's floats, decompressed */
    bool lost_client;
    job_msg proto_job;   /* this frame's settings and camera */
    double render_cpu_ms, pack_cpu_ms; /* this frame, summed over the tiles kept */
    long kill_after;     /* test hook: rank 0 dies after this many tiles of a frame */
} server;

static void tile_region(const server *s, int t, int32_t r[4]) {
    int ts = s->o->tile;
    r[0] = (t % s->tiles_x) * ts;
    r[1] = (t / s->tiles_x) * ts;
    r[2] = r[0] + ts < s->width ? r[0] + ts : s->width;
    r[3] = r[1] + ts < s->height ? r[1] + ts : s->height;
}

/* The next tile for client c: one it rendered last frame if any is pending (its caches hold that
 * part of the scene, the survey's affinity), else one nobody alive rendered, else the first pending
 * one (taken from a busier client, which balances the load). -1 when none is left. */
static int pick_tile(const server *s, int c) {
    int first = -1;
    for (int t = 0; t < s->tiles; t++) {
        if (s->state[t] != TILE_PENDING) continue;
        if (s->owner[t] == c) return t;
        if (first < 0 && (s->owner[t] < 0 || !s->clients[s->owner[t]].alive)) first = t;
    }
    if (first >= 0) return first;
    for (int t = 0; t < s->tiles; t++)
        if (s->state[t] == TILE_PENDING) return t;
    return -1;
}

static void drop_client(server *s, int c, const char *why);

static bool issue(server *s, int c, int t) {
    client *cl = &s->clients[c];
    job_msg j = s->proto_job;
    j.kind = JOB_TILE;
    j.tile = (uint32_t)t;
    tile_region(s, t, j.region);
    if (!mpir_conn_queue(&cl->conn, MSG_JOB, &j, sizeof j, NULL, 0)) {
        drop_client(s, c, "could not be sent a tile (out of memory)");
        return false;
    }
    if (cl->held == 0) cl->last_heard = mpir_now_s();
    cl->held_tile[cl->held++] = (uint32_t)t;
    s->state[t] = TILE_ISSUED;
    return true;
}

static void drop_client(server *s, int c, const char *why) {
    client *cl = &s->clients[c];
    fprintf(stderr, "raypack render: rank %d (pid %d on %s) %s; its %d tile%s go%s to the others\n", cl->rank,
            cl->hello.pid, cl->hello.host, why, cl->held, cl->held == 1 ? "" : "s", cl->held == 1 ? "es" : "");
    for (int k = 0; k < cl->held; k++)
        if (s->state[cl->held_tile[k]] == TILE_ISSUED) s->state[cl->held_tile[k]] = TILE_PENDING;
    cl->held = 0;
    cl->alive = false;
    mpir_conn_close(&cl->conn);
    s->lost_client = true;
}

/* Takes client c's complete frame (a result); false on a fatal error (message printed). */
static bool take_result(server *s, int c) {
    client *cl = &s->clients[c];
    const uint8_t *msg = cl->conn.in;
    size_t bytes = (size_t)cl->conn.hdr.bytes;
    result_msg res;
    if (cl->conn.hdr.type != MSG_RESULT || bytes < sizeof res) {
        fprintf(stderr, "raypack render: rank %d sent a %zu-byte frame of type %u, not a result\n", cl->rank, bytes,
                cl->conn.hdr.type);
        return false;
    }
    memcpy(&res, msg, sizeof res);
    if (res.kind == RESULT_ERROR) {
        fprintf(stderr, "raypack render: %.*s\n", (int)(bytes - sizeof res), (const char *)msg + sizeof res);
        return false;
    }
    int k = 0;
    while (k < cl->held && cl->held_tile[k] != res.tile) k++;
    if (res.frame != s->proto_job.frame || k == cl->held) {
        fprintf(stderr, "raypack render: rank %d returned tile %u of frame %u, which it was not rendering\n", cl->rank,
                res.tile, res.frame);
        return false;
    }
    cl->held_tile[k] = cl->held_tile[--cl->held];
    cl->last_heard = mpir_now_s();
    int32_t r[4];
    tile_region(s, (int)res.tile, r);
    size_t n = (size_t)(r[2] - r[0]) * (size_t)(r[3] - r[1]) * 3;
    float *px = s->tile_px;
    bool ok = res.floats == n &&
              wire_tile_unpack(s->codec, msg + sizeof res, bytes - sizeof res, n, s->scratch, px);
    if (!ok) {
        fprintf(stderr, "raypack render: rank %d sent a corrupt tile %u of frame %u\n", cl->rank, res.tile, res.frame);
        return false;
    }
    if (s->state[res.tile] != TILE_DONE) {
        int tw = r[2] - r[0];
        for (int y = r[1]; y < r[3]; y++)
            memcpy(s->image + ((size_t)y * (size_t)s->width + (size_t)r[0]) * 3, px + (size_t)(y - r[1]) * (size_t)tw * 3,
                   (size_t)tw * 3 * sizeof(float));
        s->state[res.tile] = TILE_DONE;
        s->owner[res.tile] = c;
        s->done++;
        cl->tiles++;
        cl->tile_ms_all += res.render_ms;
        s->render_cpu_ms += res.render_cpu_ms;
        s->pack_cpu_ms += res.pack_cpu_ms;
    }
    return true;
}

/* Reads what client c sent; false on a fatal error. A closed or broken connection drops it. */
static bool serve_input(server *s, int c) {
    client *cl = &s->clients[c];
    for (;;) {
        int rc = mpir_conn_read(&cl->conn);
        if (rc == 0) return true;
        if (rc < 0) {
            char why[200];
            snprintf(why, sizeof why, "was lost (%s)", cl->conn.err);
            drop_client(s, c, why);
            return true;
        }
        bool ok = take_result(s, c);
        mpir_conn_next(&cl->conn);
        if (!ok) return false;
        if (s->kill_after && s->done >= s->kill_after) raise(SIGKILL); /* the test of rank 0's death */
    }
}

/* Renders one frame with the clients; false on a fatal error. */
static bool server_frame(server *s) {
    int nc = s->size - 1;
    memset(s->state, TILE_PENDING, (size_t)s->tiles);
    s->done = 0;
    for (int c = 0; c < nc; c++) {
        client *cl = &s->clients[c];
        cl->tiles = 0;
        cl->in0 = cl->conn.bytes_in;
        cl->out0 = cl->conn.bytes_out;
    }
    double timeout = s->o->timeout_s;
    struct pollfd *pfd = malloc((size_t)nc * sizeof *pfd);
    int *who = malloc((size_t)nc * sizeof *who);
    bool ok = pfd && who;
    if (!ok) fprintf(stderr, "raypack render: out of memory\n");
    while (ok && s->done < s->tiles) {
        int n = 0;
        double now = mpir_now_s(), next = now + 1.0;
        for (int c = 0; c < nc; c++) {
            client *cl = &s->clients[c];
            while (cl->alive && cl->held < QUEUE_AHEAD) {
                int t = pick_tile(s, c);
                if (t < 0 || !issue(s, c, t)) break;
            }
            if (cl->alive && mpir_conn_flush(&cl->conn) < 0) {
                char why[200];
                snprintf(why, sizeof why, "was lost (%s)", cl->conn.err);
                drop_client(s, c, why);
            }
            if (!cl->alive) continue;
            if (cl->held > 0 && cl->last_heard + timeout < next) next = cl->last_heard + timeout;
            pfd[n] = (struct pollfd){.fd = cl->conn.fd, .events = (short)(POLLIN | (mpir_conn_pending(&cl->conn) ? POLLOUT : 0))};
            who[n++] = c;
        }
        if (!n) {
            fprintf(stderr, "raypack render: no render client is left (all were lost); frame %u is incomplete\n",
                    s->proto_job.frame);
            ok = false;
            break;
        }
        /* Rank 0 sleeps in poll until a client sends or a time-out is due: it takes no core from
         * clients on its node, and a result is taken the moment it arrives. */
        double wait = next - now;
        int ms = wait <= 0.0 ? 0 : (int)(wait * 1e3) + 1;
        if (poll(pfd, (nfds_t)n, ms) > 0) {
            for (int i = 0; ok && i < n; i++)
                if (pfd[i].revents) ok = serve_input(s, who[i]);
        }
        now = mpir_now_s();
        for (int c = 0; ok && c < nc; c++) {
            client *cl = &s->clients[c];
            if (cl->alive && cl->held > 0 && now - cl->last_heard > timeout) {
                char why[128];
                snprintf(why, sizeof why, "sent nothing for %.1f s while rendering", now - cl->last_heard);
                drop_client(s, c, why);
            }
        }
    }
    for (int c = 0; c < nc; c++) {
        client *cl = &s->clients[c];
        cl->bytes_in = cl->conn.bytes_in - cl->in0;
        cl->bytes_out = cl->conn.bytes_out - cl->out0;
    }
    free(pfd);
    free(who);
    return ok;
}

/* "out.png" -> "out_0007.png" for frame 7 of a sequence. */
static void frame_path(const char *output, int frames, int frame, char *buf, size_t size) {
    if (frames <= 1) {
        snprintf(buf, size, "%s", output);
        return;
    }
    const char *dot = strrchr(output, '.');
    snprintf(buf, size, "%.*s_%04d%s", (int)(dot - output), output, frame, dot);
}

/* The camera of frame i: the base camera, its eye orbiting the look point about the up axis, or
 * moved in a straight line to --to-eye / --to-look. Printed with 9 digits, which round-trip floats. */
static rp_camera frame_camera(const mpir_options *o, const rp_camera *base, int i) {
    rp_camera c = *base;
    if (o->frames <= 1) return c;
    if (o->has_to_eye || o->has_to_look) {
        double t = (double)i / (double)(o->frames - 1);
        for (int k = 0; k < 3; k++) {
            if (o->has_to_eye) c.pinhole.eye[k] = (float)((1.0 - t) * base->pinhole.eye[k] + t * o->to_eye[k]);
            if (o->has_to_look) c.pinhole.look[k] = (float)((1.0 - t) * base->pinhole.look[k] + t * o->to_look[k]);
        }
        return c;
    }
    double ang = (double)o->orbit * 3.14159265358979323846 / 180.0 * i / o->frames;
    double u[3], v[3], len = 0.0;
    for (int k = 0; k < 3; k++) len += (double)base->pinhole.up[k] * base->pinhole.up[k];
    len = sqrt(len);
    for (int k = 0; k < 3; k++) {
        u[k] = base->pinhole.up[k] / len;
        v[k] = (double)base->pinhole.eye[k] - base->pinhole.look[k];
    }
    /* Rodrigues' rotation of v about u */
    double cu[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    double d = u[0] * v[0] + u[1] * v[1] + u[2] * v[2], cs = cos(ang), sn = sin(ang);
    for (int k = 0; k < 3; k++)
        c.pinhole.eye[k] = (float)(base->pinhole.look[k] + v[k] * cs + cu[k] * sn + u[k] * d * (1.0 - cs));
    return c;
}

/* The options that choose the image size and the camera, in `raypack render`'s terms, so that the
 * sizes and cameras are its own (cli_render_size, cli_render_camera: an animated scene's camera on
 * its path at the current time, --eye, --look, --up and --fov in its place, as in render and
 * animate). */
static cli_render_setup view_setup(const mpir_options *o) {
    cli_render_setup v = {.width = o->width, .height = o->height, .has_eye = o->has_eye, .has_look = o->has_look,
                          .has_up = o->has_up, .has_fov = o->has_fov, .fov = o->fov};
    memcpy(v.eye, o->eye, sizeof v.eye);
    memcpy(v.look, o->look, sizeof v.look);
    memcpy(v.up, o->up, sizeof v.up);
    return v;
}

/* The client of a hello, if it is one of this job's ranks of this build; NULL after printing why
 * not. *fatal: the client is ours but cannot take part (another build), which ends the job. */
static client *check_hello(server *s, const mpir_conn *pc, const rendezvous_msg *rv, bool *fatal) {
    hello_msg h;
    if (pc->hdr.type != MSG_HELLO || pc->hdr.bytes < 2 * sizeof(uint32_t)) return NULL;
    memset(&h, 0, sizeof h);
    memcpy(&h, pc->in, pc->hdr.bytes < sizeof h ? (size_t)pc->hdr.bytes : sizeof h);
    h.host[sizeof h.host - 1] = '\0';
    if (h.magic != MPIR_MAGIC) return NULL;
    if (pc->hdr.bytes == sizeof h && h.token != rv->token) return NULL; /* another job's client */
    if (pc->hdr.bytes != sizeof h || h.protocol != MPIR_PROTOCOL || h.version[0] != RP_VERSION_MAJOR ||
        h.version[1] != RP_VERSION_MINOR || h.version[2] != RP_VERSION_PATCH || h.desc_bytes != sizeof(rp_render_desc)) {
        fprintf(stderr, "raypack render: rank %d (pid %d on %s) runs raypack %d.%d.%d with MPI protocol %u "
                        "(render desc %u bytes); rank 0 runs %d.%d.%d with protocol %u (%zu bytes): run the "
                        "same build on every rank\n",
                h.rank, h.pid, h.host, h.version[0], h.version[1], h.version[2], h.protocol, h.desc_bytes,
                RP_VERSION_MAJOR, RP_VERSION_MINOR, RP_VERSION_PATCH, MPIR_PROTOCOL, sizeof(rp_render_desc));
        *fatal = true;
        return NULL;
    }
    if (h.rank < 1 || h.rank >= s->size || s->clients[h.rank - 1].conn.fd >= 0) return NULL;
    client *cl = &s->clients[h.rank - 1];
    cl->hello = h;
    return cl;
}

/* A client of protocol 1 sends its hello over MPI: name it rather than wait for it in vain. */
static bool old_protocol_client(void) {
    int flag = 0;
    MPI_Status st;
    if (MPI_Iprobe(MPI_ANY_SOURCE, TAG_HELLO, MPI_COMM_WORLD, &flag, &st) != MPI_SUCCESS || !flag) return false;
    hello_msg h;
    memset(&h, 0, sizeof h);
    MPI_Recv(&h, (int)sizeof h, MPI_BYTE, st.MPI_SOURCE, TAG_HELLO, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    h.host[sizeof h.host - 1] = '\0';
    fprintf(stderr, "raypack render: rank %d (pid %d on %s) runs raypack %d.%d.%d with MPI protocol %u; rank 0 runs "
                    "%d.%d.%d with protocol %u: run the same build on every rank\n",
            st.MPI_SOURCE, h.pid, h.host, h.version[0], h.version[1], h.version[2], h.protocol, RP_VERSION_MAJOR,
            RP_VERSION_MINOR, RP_VERSION_PATCH, MPIR_PROTOCOL);
    return true;
}

/* Start-up, first part, before rank 0 loads its scene (so that the clients load theirs meanwhile):
 * a listening socket and its address to every client over MPI, the only MPI message. */
static bool server_listen(server *s, rendezvous_msg *rv, int *lfd, MPI_Request **reqs) {
    int nc = s->size - 1;
    char err[256];
    *lfd = mpir_listen(rv, err, sizeof err);
    if (*lfd < 0) {
        fprintf(stderr, "raypack render: %s\n", err);
        return false;
    }
    *reqs = malloc((size_t)nc * sizeof **reqs);
    bool ok = *reqs != NULL;
    for (int c = 0; ok && c < nc; c++)
        ok = MPI_Isend(rv, (int)sizeof *rv, MPI_BYTE, c + 1, TAG_RENDEZVOUS, MPI_COMM_WORLD, &(*reqs)[c]) == MPI_SUCCESS;
    if (!ok) fprintf(stderr, "raypack render: cannot send the clients rank 0's address\n");
    return ok;
}

/* A client whose connection failed before it was ready (sending it the scene, or reading its
 * ready): a warning, and the job goes on without it. */
static void lost_at_start(server *s, client *cl) {
    fprintf(stderr, "raypack render: warning: rank %d (pid %d on %s) was lost during start-up (%s)\n", cl->rank,
            cl->hello.pid, cl->hello.host, cl->conn.err);
    mpir_conn_close(&cl->conn);
    s->lost_client = true;
}

/* Start-up, second part: the clients' connections and hellos, then (with --mpi-bcast) the scene
 * over each connection, then every client's ready. Takes lfd and reqs. */
static bool server_start(server *s, mpir_scene *rs, const rendezvous_msg *rvp, int lfd, MPI_Request *reqs,
                         double *scene_bytes) {
    int nc = s->size - 1;
    rendezvous_msg rv = *rvp;
    enum { SPARE = 8 };
    mpir_conn *pend = calloc((size_t)(nc + SPARE), sizeof *pend); /* connections not yet identified */
    struct pollfd *pfd = malloc((size_t)(2 * nc + SPARE + 1) * sizeof *pfd);
    bool ok = reqs && pend && pfd;
    for (int i = 0; ok && i < nc + SPARE; i++) pend[i].fd = -1;
    double deadline = mpir_now_s() + s->o->timeout_s;
    int known = 0;
    while (ok && known < nc) {
        if (mpir_now_s() > deadline) {
            for (int c = 0; c < nc; c++)
                if (s->clients[c].conn.fd < 0) {
                    fprintf(stderr, "raypack render: rank %d did not answer within %.1f s (--mpi-timeout): is it "
                                    "running raypack render --mpi?\n", c + 1, s->o->timeout_s);
                    break;
                }
            ok = false;
            break;
        }
        if (old_protocol_client()) {
            ok = false;
            break;
        }
        int n = 0;
        pfd[n++] = (struct pollfd){.fd = lfd, .events = POLLIN};
        for (int i = 0; i < nc + SPARE; i++)
            if (pend[i].fd >= 0) pfd[n++] = (struct pollfd){.fd = pend[i].fd, .events = POLLIN};
        poll(pfd, (nfds_t)n, 20);
        for (;;) {
            int fd = accept(lfd, NULL, NULL);
            if (fd < 0) break;
            int slot = 0;
            while (slot < nc + SPARE && pend[slot].fd >= 0) slot++;
            if (slot == nc + SPARE) {
                close(fd);
                continue;
            }
            mpir_conn_init(&pend[slot], fd, sizeof(hello_msg) + 4096);
        }
        for (int i = 0; ok && i < nc + SPARE; i++) {
            if (pend[i].fd < 0) continue;
            int rc = mpir_conn_read(&pend[i]);
            if (rc == 0) continue;
            bool fatal = false;
            client *cl = rc > 0 ? check_hello(s, &pend[i], &rv, &fatal) : NULL;
            if (fatal) ok = false;
            if (!cl) {
                if (rc > 0 && !fatal)
                    fprintf(stderr, "raypack render: warning: a connection that is not one of this job's ranks was closed\n");
                mpir_conn_close(&pend[i]);
                continue;
            }
            mpir_conn_next(&pend[i]);
            cl->conn = pend[i];
            cl->conn.max_in = sizeof(result_msg) + wire_tile_bound((size_t)s->o->tile * (size_t)s->o->tile * 3) + 4096;
            pend[i].fd = -1;
            pend[i].in = pend[i].out = NULL;
            known++;
        }
    }
    for (int i = 0; pend && i < nc + SPARE; i++) mpir_conn_close(&pend[i]);
    close(lfd);
    /* every client has its rendezvous (it connected), so these sends are complete */
    for (int c = 0; ok && c < nc; c++) mpir_wait_until(&reqs[c], mpir_now_s() + s->o->timeout_s);
    free(reqs);
    free(pend);

    uint8_t *buf = NULL;
    size_t bytes = 0;
    if (ok && s->o->bcast) {
        if (!wire_scene_pack(&rs->data, &buf, &bytes)) {
            fprintf(stderr, "raypack render: out of memory packing the scene\n");
            ok = false;
        }
        for (int c = 0; ok && c < nc; c++) ok = mpir_conn_queue_borrowed(&s->clients[c].conn, MSG_SCENE, buf, bytes);
        *scene_bytes = (double)bytes;
    }
    /* Ready: the scene is loaded (or received) and built. Nothing moved for a time-out is an error;
     * a client lost now only leaves the others more to do. */
    int ready = 0, lost = 0;
    for (int c = 0; c < nc; c++) s->clients[c].last_heard = mpir_now_s();
    while (ok && ready + lost < nc) {
        int n = 0;
        double now = mpir_now_s();
        for (int c = 0; c < nc; c++) {
            client *cl = &s->clients[c];
            if (cl->ready || cl->conn.fd < 0) continue;
            uint64_t before = cl->conn.bytes_out;
            int rc = mpir_conn_flush(&cl->conn);
            if (cl->conn.bytes_out != before) cl->last_heard = now;
            if (rc >= 0 && now - cl->last_heard > s->o->timeout_s) {
                fprintf(stderr, "raypack render: rank %d (pid %d on %s) did not report its scene ready within %.1f s "
                                "(--mpi-timeout)\n", cl->rank, cl->hello.pid, cl->hello.host, s->o->timeout_s);
                ok = false;
                break;
            }
            if (rc < 0) {
                lost_at_start(s, cl);
                lost++;
                continue;
            }
            pfd[n++] = (struct pollfd){.fd = cl->conn.fd, .events = (short)(POLLIN | (rc == 0 ? POLLOUT : 0))};
        }
        if (!ok || !n) break;
        poll(pfd, (nfds_t)n, 20);
        for (int c = 0; ok && c < nc; c++) {
            client *cl = &s->clients[c];
            if (cl->ready || cl->conn.fd < 0) continue;
            int rc = mpir_conn_read(&cl->conn);
            if (rc == 0) continue;
            if (rc < 0) {
                lost_at_start(s, cl);
                lost++;
                continue;
            }
            ready_msg r;
            memset(&r, 0, sizeof r);
            if (cl->conn.hdr.type != MSG_READY || cl->conn.hdr.bytes != sizeof r) {
                fprintf(stderr, "raypack render: rank %d sent a frame of type %u where its ready was due\n", cl->rank,
                        cl->conn.hdr.type);
                ok = false;
                break;
            }
            memcpy(&r, cl->conn.in, sizeof r);
            mpir_conn_next(&cl->conn);
            r.err[sizeof r.err - 1] = '\0';
            if (!r.ok) {
                fprintf(stderr, "raypack render: rank %d (pid %d on %s) has no scene: %s\n", cl->rank, cl->hello.pid,
                        cl->hello.host, r.err);
                ok = false;
            } else if (r.triangles != rs->data.triangle_count) {
                fprintf(stderr, "raypack render: rank %d loaded %llu triangles from %s, rank 0 %zu: not the same scene\n",
                        cl->rank, (unsigned long long)r.triangles, s->o->scene ? s->o->scene : "(built-in room)",
                        rs->data.triangle_count);
                ok = false;
            } else {
                cl->threads = r.threads;
                cl->ready = cl->alive = true;
                ready++;
            }
        }
    }
    if (ok && ready == 0) {
        fprintf(stderr, "raypack render: every render client was lost during start-up\n");
        ok = false;
    }
    free(pfd);
    free(buf); /* every ready client has received it all */
    return ok;
}

/* Ends the clients. After a lost client MPI_Finalize would wait for it forever, so the live ones
 * are told to leave without it (q.tile = 1), and a lost one still running on this host (it hangs
 * rather than died) is killed; true when every lost client was on this host, so that the job can end
 * without MPI_Abort. */
static bool quit_clients(server *s) {
    job_msg q = {.kind = JOB_QUIT, .tile = s->lost_client ? 1u : 0u};
    char host[64] = "";
    gethostname(host, sizeof host - 1);
    bool local = true;
    for (int c = 0; c < s->size - 1; c++) {
        client *cl = &s->clients[c];
        if (cl->alive) {
            if (mpir_conn_queue(&cl->conn, MSG_JOB, &q, sizeof q, NULL, 0)) mpir_conn_send_idle(&cl->conn, s->o->timeout_s);
        } else if (strcmp(cl->hello.host, host) == 0 && cl->hello.pid > 1) {
            kill((pid_t)cl->hello.pid, SIGKILL);
        } else {
            local = false;
        }
        mpir_conn_close(&cl->conn);
    }
    return local;
}

int mpir_server_run(const mpir_options *o, int size) {
    double t0 = cli_now_ms();
    int status = CLI_EXIT_FAILURE;
    server s;
    memset(&s, 0, sizeof s);
    s.o = o;
    s.size = size;
    s.kill_after = mpir_test_hook("KILL", 0);
    mpir_scene rs;
    memset(&rs, 0, sizeof rs);
    mpir_tile_worker w = {0};
    char err[512] = "";
    rendezvous_msg rv;
    int lfd = -1;
    MPI_Request *reqs = NULL;
    if (size > 1 && !server_listen(&s, &rv, &lfd, &reqs)) return CLI_EXIT_FAILURE;
    /* With clients rank 0 only hands out tiles: one thread, so it does not take their cores. */
    if (!mpir_scene_load(&rs, o, true, err, sizeof err) || !mpir_scene_build(&rs, o, size > 1 ? 1 : o->threads, err, sizeof err)) {
        fprintf(stderr, "%s%s\n", strstr(err, "error:") ? "" : "raypack render: ", err);
        mpir_scene_free(&rs);
        free(reqs);
        return CLI_EXIT_FAILURE;
    }
    double load_ms = cli_now_ms() - t0;
    const rp_animation_data *anim = rs.data.animation;
    int frames = o->frames > 0 ? o->frames : 1;
    /* An animated sequence follows the scene's camera path; the orbit is for a still scene (or one
     * held at --anim-time), so asking for both is a mistake, not a choice to guess at. */
    bool play = anim && !o->has_anim_time;
    const char *moved = o->has_orbit ? "--orbit" : o->has_to_eye ? "--to-eye" : o->has_to_look ? "--to-look" : NULL;
    if (o->has_anim_time && !anim) {
        fprintf(stderr, "raypack render: --anim-time: the scene is not animated (no AFF keyframes, tpa or camera path)\n");
        status = CLI_EXIT_USAGE;
    } else if (play && frames > 1 && moved) {
        fprintf(stderr, "raypack render: %s moves the camera of a still scene, but %s is animated: its frames follow "
                        "the animation and its camera path (hold it with --anim-time T to move the camera)\n", moved,
                o->scene);
        status = CLI_EXIT_USAGE;
    }
    if (status == CLI_EXIT_USAGE) {
        mpir_scene_free(&rs);
        free(reqs);
        return status;
    }
    const cli_render_setup view = view_setup(o);
    int wd, ht;
    cli_render_size(&view, &rs.data, &wd, &ht);
    s.width = wd;
    s.height = ht;
    s.tiles_x = (wd + o->tile - 1) / o->tile;
    s.tiles_y = (ht + o->tile - 1) / o->tile;
    s.tiles = s.tiles_x * s.tiles_y;
    s.state = calloc((size_t)s.tiles, 1);
    s.owner = malloc((size_t)s.tiles * sizeof *s.owner);
    s.image = malloc((size_t)wd * (size_t)ht * 3 * sizeof(float));
    s.scratch = malloc((size_t)o->tile * (size_t)o->tile * 3 * sizeof(float));
    s.clients = calloc((size_t)(size > 1 ? size - 1 : 1), sizeof *s.clients);
    for (int c = 0; s.clients && c < size - 1; c++) {
        s.clients[c].rank = c + 1;
        s.clients[c].conn.fd = -1;
    }
    s.codec = wire_codec_new();
    s.tile_px = malloc((size_t)o->tile * (size_t)o->tile * 3 * sizeof(float));
    if (!s.state || !s.owner || !s.image || !s.scratch || !s.clients || !s.codec || !s.tile_px) {
        fprintf(stderr, "raypack render: out of memory for a %dx%d image\n", wd, ht);
        goto done;
    }
    for (int t = 0; t < s.tiles; t++) s.owner[t] = -1;
    double scene_bytes = 0.0;
    if (size > 1 && !server_start(&s, &rs, &rv, lfd, reqs, &scene_bytes)) goto done;
    if (!o->quiet) {
        printf("mpi      %d ranks: rank 0 serves %d tiles of %dx%d per frame (%dx%d image) to %d client%s", size,
               s.tiles, o->tile, o->tile, wd, ht, size - 1, size == 2 ? "" : "s");
        if (size == 1) printf(" (none: rank 0 renders alone)");
        printf("; scene %s%s, load+build %.1f ms", o->bcast && size > 1 ? "broadcast" : "loaded by every rank",
               scene_bytes > 0.0 ? "" : "", load_ms);
        if (scene_bytes > 0.0) printf(", %.2f MiB sent", scene_bytes / 1048576.0);
        printf("\n");
        for (int c = 0; c < size - 1; c++) {
            if (s.clients[c].alive)
                printf("client   rank %d: pid %d on %s, %d threads\n", s.clients[c].rank, s.clients[c].hello.pid,
                       s.clients[c].hello.host, s.clients[c].threads);
            else
                printf("client   rank %d: pid %d on %s, lost during start-up\n", s.clients[c].rank,
                       s.clients[c].hello.pid, s.clients[c].hello.host);
        }
        fflush(stdout); /* who the clients are, before the frames: a supervisor (or the kill test) reads it */
    }
    if (!o->quiet && anim) {
        if (play)
            printf("anim     %d frame%s of the animation over [%.9g, %.9g] (as raypack animate --frames %d), the camera "
                   "on its path\n", frames, frames == 1 ? "" : "s", (double)anim->start, (double)anim->end, frames);
        else
            printf("anim     every frame at time %.9g\n", (double)o->anim_time);
        fflush(stdout);
    }
    double total_ms = 0.0;
    for (int f = 0; f < frames; f++) {
        /* every rank moves the scene to the frame's time before its tiles: here, and each client
         * when the frame's first tile reaches it */
        float ft = o->has_anim_time ? o->anim_time : rp_anim_frame_time(anim, f, frames);
        if (!mpir_scene_frame(&rs, ft, err, sizeof err)) {
            fprintf(stderr, "raypack render: frame %d: %s\n", f, err);
            goto done;
        }
        rp_camera base = cli_render_camera(&view, rs.scene);
        rp_camera fc = play ? base : frame_camera(o, &base, f);
        /* as `raypack render`: a camera with no frame (an up along the view, the eye on the look-at
         * point, a path through it) or a scene past the float tests' reach is an error, not an image */
        if (fc.type == RP_CAMERA_PINHOLE) {
            int cs = cli_camera_check(MPIR_CMD, o->scene, fc.pinhole.eye, fc.pinhole.look, fc.pinhole.up,
                                      o->has_eye || o->has_to_eye || (o->has_orbit && f),
                                      o->has_look || o->has_to_look, o->has_up);
            if (cs != CLI_EXIT_OK) {
                if (frames > 1) fprintf(stderr, "raypack render: (frame %d's camera)\n", f);
                status = cs;
                goto done;
            }
        }
        if (!cli_scene_in_reach(MPIR_CMD, o->scene, rs.scene, &fc)) goto done;
        s.proto_job = (job_msg){.frame = (uint32_t)f, .width = wd, .height = ht, .spp = o->spp,
                                .animated = anim != NULL, .anim_time = ft,
                                .integrator = (int32_t)o->integrator, .packet = o->packet, .camera = fc,
                                .raw_planes = o->raw_planes, .ao_distance = o->ao_distance,
                                .ir = {.interleave = o->ir_interleave, .vpls = o->ir_vpls, .filter = o->ir_filter,
                                       .clamp = o->ir_clamp, .rr = o->ir_rr},
                                /* rp_render_desc: 0 is the default depth (5), negative is none */
                                .max_depth = o->max_depth < 0 ? 0 : (o->max_depth == 0 ? -1 : o->max_depth)};
        double f0 = cli_now_ms(), c0 = mpir_cpu_ms();
        s.render_cpu_ms = s.pack_cpu_ms = 0.0;
        if (size == 1) {
            memset(s.state, TILE_PENDING, (size_t)s.tiles);
            for (int t = 0; t < s.tiles; t++) {
                job_msg j = s.proto_job;
                j.tile = (uint32_t)t;
                tile_region(&s, t, j.region);
                rp_render_stats rst;
                if (!mpir_tile_render(&w, rs.scene, &j, &rst)) {
                    fprintf(stderr, "raypack render: rendering failed (out of memory?)\n");
                    goto done;
                }
                int tw = j.region[2] - j.region[0];
                for (int y = j.region[1]; y < j.region[3]; y++)
                    memcpy(s.image + ((size_t)y * (size_t)wd + (size_t)j.region[0]) * 3,
                           w.tile + (size_t)(y - j.region[1]) * (size_t)tw * 3, (size_t)tw * 3 * sizeof(float));
            }
        } else if (!server_frame(&s)) {
            goto done;
        }
        double frame_ms = cli_now_ms() - f0, server_cpu_ms = mpir_cpu_ms() - c0;
        total_ms += frame_ms;
        char path[1100];
        frame_path(o->output, frames, f, path, sizeof path);
        /* 8-bit files: the exposure and tone map of `raypack render`, after the last tile */
        const char *dot = strrchr(path, '.');
        if (dot && (strcasecmp(dot, ".png") == 0 || strcasecmp(dot, ".ppm") == 0))
            rp_film_tonemap(s.image, (size_t)wd * (size_t)ht, 3, o->exposure, o->tonemap);
        if (!rp_image_write(path, wd, ht, 3, s.image, err, sizeof err)) {
            fprintf(stderr, "raypack render: %s\n", err);
            goto done;
        }
        if (!o->quiet) {
            uint64_t in = 0, out = 0;
            for (int c = 0; c < size - 1; c++) {
                in += s.clients[c].bytes_in;
                out += s.clients[c].bytes_out;
            }
            char when[96] = "";
            if (anim)
                snprintf(when, sizeof when, "anim time %.9g (rank 0's update %.3f ms); ", (double)ft,
                         rs.update.update_ms);
            printf("frame    %d: %s, %.1f ms, received %.1f KiB (%.2f of the raw floats), sent %.1f KiB; %scamera "
                   "eye %.9g,%.9g,%.9g look %.9g,%.9g,%.9g up %.9g,%.9g,%.9g fov %.9g\n",
                   f, path, frame_ms, (double)in / 1024.0,
                   (double)in / ((double)wd * ht * 3 * sizeof(float)), (double)out / 1024.0, when, fc.pinhole.eye[0],
                   fc.pinhole.eye[1], fc.pinhole.eye[2], fc.pinhole.look[0], fc.pinhole.look[1], fc.pinhole.look[2],
                   fc.pinhole.up[0], fc.pinhole.up[1], fc.pinhole.up[2], fc.pinhole.fov_deg);
            if (size > 1) {
                /* what the frame cost in CPU time: rendering (as a single process would) against
                 * what distribution adds (packing on the clients, serving on rank 0) */
                printf("cost     frame %d: clients' CPU in rp_render %.1f ms, packing %.1f ms; rank 0's CPU %.1f ms; "
                       "overhead %.2f%%\n", f, s.render_cpu_ms, s.pack_cpu_ms, server_cpu_ms,
                       s.render_cpu_ms > 0.0 ? 100.0 * (s.pack_cpu_ms + server_cpu_ms) / s.render_cpu_ms : 0.0);
                printf("share    frame %d:", f);
                for (int c = 0; c < size - 1; c++)
                    printf(" rank %d %.1f%% (%llu KiB in, %llu KiB out)%s", s.clients[c].rank,
                           100.0 * (double)s.clients[c].tiles / s.tiles, (unsigned long long)(s.clients[c].bytes_in + 512) / 1024,
                           (unsigned long long)(s.clients[c].bytes_out + 512) / 1024, s.clients[c].alive ? "" : " (lost)");
                printf("\n");
            }
        }
        fflush(stdout); /* a frame's report as it ends: a supervisor (or the kill test) reads it */
        for (int c = 0; c < size - 1; c++) {
            client *cl = &s.clients[c];
            cl->tiles_all += cl->tiles;
            cl->bytes_in_all += cl->bytes_in;
            cl->bytes_out_all += cl->bytes_out;
        }
    }
    if (!o->quiet) {
        printf("total    %d frame%s in %.1f ms, %.1f ms per frame", frames, frames == 1 ? "" : "s", total_ms,
               total_ms / frames);
        for (int c = 0; c < size - 1; c++) {
            client *cl = &s.clients[c];
            printf("%s rank %d: %llu tiles, %.3f ms per tile, %.1f KiB in, %.1f KiB out", c ? ";" : "\n        ",
                   cl->rank, (unsigned long long)cl->tiles_all, cl->tiles_all ? cl->tile_ms_all / (double)cl->tiles_all : 0.0,
                   (double)cl->bytes_in_all / 1024.0, (double)cl->bytes_out_all / 1024.0);
        }
        printf("\n");
    }
    status = CLI_EXIT_OK;
done:
    fflush(stdout);
    bool all_local = status == CLI_EXIT_OK && size > 1 ? quit_clients(&s) : true;
    for (int c = 0; s.clients && c < size - 1; c++) mpir_conn_close(&s.clients[c].conn);
    mpir_tile_worker_free(&w);
    free(s.state);
    free(s.owner);
    free(s.image);
    free(s.scratch);
    free(s.clients);
    free(s.tile_px);
    wire_codec_free(s.codec);
    mpir_scene_free(&rs);
    if (s.lost_client && status == CLI_EXIT_OK) return all_local ? SERVER_LOST_LOCAL : SERVER_LOST_REMOTE;
    return status;
}
