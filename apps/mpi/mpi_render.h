/* Internals of `raypack render --mpi` (apps/mpi): the messages ranks exchange, the options, and
 * what the server (mpi_server.c) and the clients (mpi_client.c) share: transfers with deadlines
 * (mpi_net.c) and a rank's scene and tile rendering (mpi_tile.c). mpi_render.c has the design. */
#ifndef RP_MPI_RENDER_H
#define RP_MPI_RENDER_H

#include <mpi.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "raypack.h"
#include "raypack_io.h"
#include "cli.h"
#include "raypack_render.h"
#include "wire.h"

#define MPIR_CMD "render"

/* Bumped whenever a message below changes; the handshake refuses a client of another protocol.
 * Protocol 1 sent every message over MPI; 2 uses MPI only to tell clients rank 0's address; 3 adds
 * the frame's animation time to jobs and the animation to the broadcast scene (wire format 2). */
#define MPIR_PROTOCOL 3u
#define MPIR_MAGIC 0x4d435052u /* "RPCM" */

/* TAG_RENDEZVOUS is the one MPI message (rank 0 to each client); the others are frames on the
 * client's TCP connection (mpi_net.c). TAG_HELLO is kept so that rank 0 can name a protocol-1 client. */
enum { TAG_HELLO = 1, TAG_RENDEZVOUS = 5 };
enum { MSG_HELLO = 1, MSG_READY = 2, MSG_JOB = 3, MSG_RESULT = 4, MSG_SCENE = 5 };
enum { JOB_TILE = 1, JOB_QUIT = 2 };
enum { RESULT_TILE = 1, RESULT_ERROR = 2 };

/* Rank 0 -> each client over MPI: where to connect, and the token that proves a connection is
 * one of this job's ranks. The first two fields keep their place in every protocol. */
typedef struct rendezvous_msg {
    uint32_t magic, protocol;
    uint64_t token;
    uint32_t port;           /* TCP, host order */
    uint32_t addr_count;
    uint32_t addr[8];        /* rank 0's IPv4 addresses, network order, loopback last */
    char host[64];
} rendezvous_msg;

/* Client -> server, the first frame on its connection: who it is and which build it runs. */
typedef struct hello_msg {
    uint32_t magic, protocol;
    int32_t version[3];
    uint32_t desc_bytes; /* sizeof(rp_render_desc): the same struct layout on both ends */
    int32_t pid;
    char host[64];
    int32_t rank;
    uint64_t token;
} hello_msg;

/* Client -> server once it has the scene and its BVH, or why it has not. */
typedef struct ready_msg {
    int32_t ok;
    int32_t threads;
    uint64_t triangles;
    char err[512];
} ready_msg;

/* Server -> client: one tile of one frame, with everything needed to render it, or quit. */
typedef struct job_msg {
    uint32_t kind;
    uint32_t frame, tile;
    int32_t region[4];
    int32_t width, height, spp, integrator, max_depth, packet;
    int32_t raw_planes; /* wire_tile_pack: 3 (--mpi-compress fast) or 2 (small) */
    rp_camera camera;
    rp_ir_desc ir;
    float ao_distance;
    int32_t animated;   /* 1: the scene is animated; a rank moves it to anim_time before the frame's tiles */
    float anim_time;
} job_msg;

/* Client -> server: a finished tile (followed by its compressed floats) or an error (its text). */
typedef struct result_msg {
    uint32_t kind;
    uint32_t frame, tile;
    int32_t region[4];
    double render_ms;         /* wall time of rp_render */
    double render_cpu_ms;     /* CPU time of the client's process (all its threads) in rp_render */
    double pack_cpu_ms;       /* CPU time copying the region out and compressing it */
    uint64_t floats, rays;
} result_msg;

typedef struct mpir_options {
    const char *scene, *output;
    int width, height, spp, max_depth, threads, isa, packet;
    rp_integrator_type integrator;
    bool has_eye, has_look, has_up, has_fov, has_to_eye, has_to_look;
    float eye[3], look[3], up[3], fov, to_eye[3], to_look[3];
    int frames;
    float orbit;
    bool has_orbit;
    /* animated scenes: the time every frame holds (else frame f of K is at `raypack animate`'s time) */
    bool has_anim_time;
    float anim_time;
    bool bcast, quiet;
    int tile;
    float timeout_s;
    int raw_planes;
    /* as in `raypack render` */
    int ir_interleave, ir_vpls, ir_filter;
    float ir_clamp, ir_rr, ao_distance, exposure;
    rp_tonemap tonemap;
    cli_medium_opts vol;   /* --density-scale, --albedo, --hg-g, --medium-box, --vdb-grid */
    const char *env;       /* every rank reads it, with --mpi-bcast too */
    bool has_env_scale;
    float env_scale[3];
} mpir_options;

/* ---- a rank's scene and tiles (mpi_tile.c) ---- */

typedef struct mpir_scene {
    rp_scene_data data;
    bool builtin;
    rp_device *device;
    rp_render_scene *scene;
    rp_render_update_stats update; /* of the last mpir_scene_frame of an animated scene */
} mpir_scene;

typedef struct mpir_tile_worker {
    float *frame;        /* width * height * 3: rp_render writes the region in place */
    int width, height;
    float *tile;         /* the region's floats, contiguous */
    uint8_t *scratch, *packed;
    size_t tile_cap, packed_cap;
    wire_codec *codec;
    double render_cpu_ms;  /* of the last tile */
} mpir_tile_worker;

/* Loads o->scene (NULL: the built-in room) into s->data with o->vol's --vdb-grid and --medium-box;
 * warn: print the loader's warnings on stderr (rank 0 only); false with a message in err. */
bool mpir_scene_load(mpir_scene *s, const mpir_options *o, bool warn, char *err, size_t err_size);
/* Makes the device and commits the render scene of s->data; false with a message in err. */
bool mpir_scene_build(mpir_scene *s, const mpir_options *o, int threads, char *err, size_t err_size);
/* The per-frame scene update, on rank 0 and every client before a frame's tiles render (a client
 * calls it when its first tile of that frame comes): an animated scene (BART's) moves to the frame's
 * time with rp_render_scene_set_time (instances placed, `tpa` refits, lights, camera path); a still
 * one stays. False with a message in err. */
bool mpir_scene_frame(mpir_scene *s, float time, char *err, size_t err_size);
/* Frees what load and build made. */
void mpir_scene_free(mpir_scene *s);
/* Renders job's region and leaves its floats in w->tile, row by row; false when out of memory. */
bool mpir_tile_render(mpir_tile_worker *w, rp_render_scene *scene, const job_msg *j, rp_render_stats *st);
/* Frees a worker's buffers. */
void mpir_tile_worker_free(mpir_tile_worker *w);

/* ---- our transport (mpi_net.c): frames on TCP, polled against deadlines ---- */

/* A frame's header on the stream: its type, a check word, the payload's size. */
typedef struct net_header {
    uint32_t type, check;
    uint64_t bytes;
} net_header;

/* One end of a connection, non-blocking: frames queued for sending, and the frame being read. */
typedef struct mpir_conn {
    int fd;
    uint8_t *out;               /* queued bytes, sent from out_off */
    size_t out_len, out_off, out_cap;
    const uint8_t *borrowed;    /* then these (the scene, not copied per client), borrowed_len bytes */
    size_t borrowed_len, borrowed_off;
    net_header hdr;             /* the frame being read */
    size_t hdr_have, in_have, in_cap;
    uint8_t *in;                /* its payload */
    uint64_t max_in;            /* largest payload accepted */
    uint64_t bytes_in, bytes_out;
    char err[160];              /* why the connection ended */
} mpir_conn;

/* Seconds on a monotonic clock. */
double mpir_now_s(void);
/* CPU time of this process, all threads, in milliseconds. */
double mpir_cpu_ms(void);
/* Sleeps us microseconds. */
void mpir_sleep_us(long us);
/* Test hooks for the fault tests (tests/mpi_test_render.c): RAYPACK_MPI_TEST_<NAME>=RANK[:VALUE]
 * makes that rank misbehave; returns VALUE (1 without one) for this rank, else 0. */
long mpir_test_hook(const char *name, int rank);
/* Waits for a non-blocking MPI request until deadline (mpir_now_s); false on time-out. */
bool mpir_wait_until(MPI_Request *req, double deadline);

/* A listening TCP socket on every interface (port 0: any) and the rendezvous that names it; -1
 * with a message in err. */
int mpir_listen(rendezvous_msg *rv, char *err, size_t err_size);
/* Connects to rank 0 at one of rv's addresses by deadline; -1 with a message in err. */
int mpir_connect(const rendezvous_msg *rv, double deadline, char *err, size_t err_size);
/* Takes a connected socket (non-blocking from now on); max_in bounds the payloads it accepts. */
void mpir_conn_init(mpir_conn *c, int fd, uint64_t max_in);
/* Closes the socket and frees the buffers. */
void mpir_conn_close(mpir_conn *c);
/* Queues a frame of type with payload a then b (either may be empty); false when out of memory. */
bool mpir_conn_queue(mpir_conn *c, uint32_t type, const void *a, size_t an, const void *b, size_t bn);
/* Queues a frame whose payload stays the caller's until it is sent; nothing can be queued behind
 * it until then. */
bool mpir_conn_queue_borrowed(mpir_conn *c, uint32_t type, const void *buf, size_t n);
/* True while queued bytes wait to be sent. */
bool mpir_conn_pending(const mpir_conn *c);
/* Sends what the socket takes now: 1 all sent, 0 some left, -1 the connection failed (c->err). */
int mpir_conn_flush(mpir_conn *c);
/* Reads what has arrived: 1 a frame is complete (c->hdr.type, c->in, c->hdr.bytes; call
 * mpir_conn_next before reading on), 0 not yet, -1 closed or broken (c->err). */
int mpir_conn_read(mpir_conn *c);
/* Forgets the complete frame, to read the next. */
void mpir_conn_next(mpir_conn *c);
/* Blocking forms for the clients: send everything queued, or wait for one frame, giving up when
 * nothing moved for idle_s seconds (0 on time-out, -1 when the connection failed). */
int mpir_conn_send_idle(mpir_conn *c, double idle_s);
int mpir_conn_recv_idle(mpir_conn *c, double idle_s);

/* ---- the two roles ---- */

/* mpir_server_run's results beyond the exit statuses: every frame written, but a client was lost (and
 * any lost one still running was on this host and is killed, or was elsewhere). */
enum { SERVER_LOST_LOCAL = -1, SERVER_LOST_REMOTE = -2 };

/* A render client (ranks 1..N-1); *no_finalize says rank 0 asked it to leave without MPI_Finalize. */
int mpir_client_run(const mpir_options *o, int rank, bool *no_finalize);
/* The display server (rank 0): an exit status, or a SERVER_LOST_ value. */
int mpir_server_run(const mpir_options *o, int size);

#endif
