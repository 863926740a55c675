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
#include "raypack_render.h"
#include "wire.h"

#define MPIR_CMD "render"

/* Bumped whenever a message below changes; the handshake refuses a client of another protocol. */
#define MPIR_PROTOCOL 1u
#define MPIR_MAGIC 0x4d435052u /* "RPCM" */

enum { TAG_HELLO = 1, TAG_READY = 2, TAG_JOB = 3, TAG_RESULT = 4 };
enum { JOB_TILE = 1, JOB_QUIT = 2 };
enum { RESULT_TILE = 1, RESULT_ERROR = 2 };

/* Client -> server, first thing after MPI_Init: who it is and which build it runs. */
typedef struct hello_msg {
    uint32_t magic, protocol;
    int32_t version[3];
    uint32_t desc_bytes; /* sizeof(rp_render_desc): the same struct layout on both ends */
    int32_t pid;
    char host[64];
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
    bool bcast, quiet;
    int tile;
    float timeout_s;
    int raw_planes;
} mpir_options;

/* ---- a rank's scene and tiles (mpi_tile.c) ---- */

typedef struct mpir_scene {
    rp_scene_data data;
    bool builtin;
    rp_device *device;
    rp_render_scene *scene;
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

/* Loads SCENE (NULL: the built-in room) into s->data; false with a message in err. */
bool mpir_scene_load(mpir_scene *s, const char *path, char *err, size_t err_size);
/* Makes the device and commits the render scene of s->data; false with a message in err. */
bool mpir_scene_build(mpir_scene *s, const mpir_options *o, int threads, char *err, size_t err_size);
/* Frees what load and build made. */
void mpir_scene_free(mpir_scene *s);
/* Renders job's region and leaves its floats in w->tile, row by row; false when out of memory. */
bool mpir_tile_render(mpir_tile_worker *w, rp_render_scene *scene, const job_msg *j, rp_render_stats *st);
/* Frees a worker's buffers. */
void mpir_tile_worker_free(mpir_tile_worker *w);

/* ---- transfers with deadlines (mpi_net.c) ---- */

/* CPU time of this process, all threads, in milliseconds. */
double mpir_cpu_ms(void);
/* Sleeps us microseconds. */
void mpir_sleep_us(long us);
/* Test hooks for the fault tests (tests/mpi_test_render.c): RAYPACK_MPI_TEST_<NAME>=RANK[:VALUE]
 * makes that rank misbehave; returns VALUE (1 without one) for this rank, else 0. */
long mpir_test_hook(const char *name, int rank);
/* Waits for a non-blocking request until deadline (MPI_Wtime seconds); false on time-out. */
bool mpir_wait_until(MPI_Request *req, double deadline);
/* A send that gives up at deadline instead of hanging on a dead peer. */
bool mpir_send_until(const void *buf, size_t bytes, int dest, int tag, double deadline);
/* Waits for a message with tag from src (or MPI_ANY_SOURCE) until deadline; fills status. */
bool mpir_probe_until(int src, int tag, double deadline, MPI_Status *st);
/* A broadcast from rank 0 that times out (chunks below INT_MAX bytes, each an MPI_Ibcast). */
bool mpir_bcast_until(void *buf, size_t bytes, double deadline);

/* ---- the two roles ---- */

/* mpir_server_run's results beyond the exit statuses: every frame written, but a client was lost (and
 * any lost one still running was on this host and is killed, or was elsewhere). */
enum { SERVER_LOST_LOCAL = -1, SERVER_LOST_REMOTE = -2 };

/* A render client (ranks 1..N-1); *no_finalize says rank 0 asked it to leave without MPI_Finalize. */
int mpir_client_run(const mpir_options *o, int rank, bool *no_finalize);
/* The display server (rank 0): an exit status, or a SERVER_LOST_ value. */
int mpir_server_run(const mpir_options *o, int size);

#endif
