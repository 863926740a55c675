/* `mpirun -np N raypack render SCENE --mpi`: distributed rendering as the survey describes OpenRT's
 * cluster (Recheis, sec. 5.2; Wald et al. 2001): rank 0 is the display server, every other rank a
 * render client with the device's threads. The server cuts each frame into tiles and hands them out
 * dynamically, keeping one tile queued ahead on every client so that none waits for its next job;
 * clients send finished tiles back compressed (wire.c), and the server writes the image through the
 * same rp_image_write as `raypack render`. A pixel's value depends only on the pixel (the
 * deterministic sampler), so the image is bit-identical to the single process for any N.
 *
 * Faults, with Open MPI 4.1 (no ULFM): the server never blocks on a client. Every send and receive
 * is non-blocking and polled against a deadline, so a client that dies (kill -9) or stops answering
 * is noticed when it has sent nothing for --mpi-timeout seconds while it holds tiles; those tiles
 * go back to the queue and the others render them, and the frame comes out the same. That needs the
 * job to outlive the client: `mpirun --enable-recovery` (without it mpirun kills every rank when one
 * dies). MPI_Finalize would then wait for the dead rank forever, so after the last frame is written a
 * server that lost a client tells the others to leave without it, kills a lost client that still
 * runs on its host (one that hangs), and leaves too; a lost client on another host is stopped with
 * MPI_Abort(0) (exit status 0). The
 * server's own death ends the job (mpirun kills the clients; under --enable-recovery each client
 * gives up after hearing nothing for 4 timeouts). */
#include "cli.h"

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

#include "raypack.h"
#include "raypack_io.h"
#include "raypack_render.h"
#include "wire.h"

static const char *const CMD = "render";

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

typedef struct mpi_options {
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
} mpi_options;

/* ---- small helpers ---- */

/* CPU time of this process, all threads, in milliseconds. */
static double cpu_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static void sleep_us(long us) {
    struct timespec ts = {.tv_sec = us / 1000000, .tv_nsec = (us % 1000000) * 1000};
    nanosleep(&ts, NULL);
}

/* Test hooks for the fault tests (tests/test_mpi.c): RAYPACK_MPI_TEST_<NAME>=RANK[:VALUE] makes that
 * rank misbehave; returns VALUE (1 without one) for this rank, else 0. */
static long test_hook(const char *name, int rank) {
    char var[64];
    snprintf(var, sizeof var, "RAYPACK_MPI_TEST_%s", name);
    const char *v = getenv(var);
    if (!v) return 0;
    char *end;
    long r = strtol(v, &end, 10);
    if (end == v || r != rank) return 0;
    return *end == ':' ? strtol(end + 1, NULL, 10) : 1;
}

/* Waits for a non-blocking request until deadline (MPI_Wtime seconds); false on time-out. */
static bool wait_until(MPI_Request *req, double deadline) {
    for (;;) {
        int done = 0;
        if (MPI_Test(req, &done, MPI_STATUS_IGNORE) != MPI_SUCCESS) return false;
        if (done) return true;
        if (MPI_Wtime() > deadline) return false;
        sleep_us(100);
    }
}

/* Blocking-style send that gives up at deadline instead of hanging on a dead peer. */
static bool send_until(const void *buf, size_t bytes, int dest, int tag, double deadline) {
    MPI_Request req;
    if (MPI_Isend(buf, (int)bytes, MPI_BYTE, dest, tag, MPI_COMM_WORLD, &req) != MPI_SUCCESS) return false;
    return wait_until(&req, deadline);
}

/* Waits for a message with tag from src (or any) until deadline; fills status. */
static bool probe_until(int src, int tag, double deadline, MPI_Status *st) {
    for (;;) {
        int flag = 0;
        if (MPI_Iprobe(src, tag, MPI_COMM_WORLD, &flag, st) != MPI_SUCCESS) return false;
        if (flag) return true;
        if (MPI_Wtime() > deadline) return false;
        sleep_us(100);
    }
}

/* A broadcast from rank 0 that times out: chunks below INT_MAX bytes, each an MPI_Ibcast. */
static bool bcast_until(void *buf, size_t bytes, double deadline) {
    const size_t chunk = (size_t)1 << 30;
    for (size_t off = 0; off < bytes; off += chunk) {
        size_t n = bytes - off < chunk ? bytes - off : chunk;
        MPI_Request req;
        if (MPI_Ibcast((uint8_t *)buf + off, (int)n, MPI_BYTE, 0, MPI_COMM_WORLD, &req) != MPI_SUCCESS) return false;
        if (!wait_until(&req, deadline)) return false;
    }
    return true;
}

/* ---- options ---- */

static void mpi_usage(FILE *out) {
    fprintf(out,
            "usage: mpirun -np N raypack render [SCENE] --mpi [options]\n"
            "\n"
            "Distributed rendering: rank 0 hands image tiles to ranks 1..N-1 (each with the device's\n"
            "threads) and writes the image, identical to `raypack render`'s. With -np 1 rank 0 renders\n"
            "alone. Use `mpirun --enable-recovery` so that a client's death does not end the job: its\n"
            "tiles are then rendered by the others.\n"
            "\n"
            "options (as in `raypack render`): -o FILE (.png .ppm .pfm), --width W, --height H, --spp N,\n"
            "  --integrator eyelight|whitted, --max-depth N, --packet N, --threads N, --isa NAME,\n"
            "  --eye X,Y,Z --look X,Y,Z --up X,Y,Z --fov DEG, --quiet\n"
            "MPI options:\n"
            "  --mpi                  distributed rendering (needed)\n"
            "  --mpi-bcast            only rank 0 reads SCENE and broadcasts its data (else every rank\n"
            "                         loads the same path)\n"
            "  --mpi-tile N           tile side handed to a client, 16..1024 [64]\n"
            "  --mpi-compress fast|small\n"
            "                         how tiles travel: fast deflates only each float's sign and exponent\n"
            "                         byte (kitchen: 0.77 of the floats' bytes, 11 ms CPU per 1024x1024\n"
            "                         frame), small also the top mantissa byte (0.66, 41 ms) [fast]\n"
            "  --mpi-timeout S        seconds a client may stay silent while it holds tiles (then its\n"
            "                         tiles go to the others), and the limit of the start-up handshake [10]\n"
            "  --frames N             render a sequence of N frames, 1..100000, written as FILE_0000.EXT...\n"
            "                         [1]; the camera orbits the look point about the up axis\n"
            "  --orbit DEG            degrees the eye turns over the sequence [360]\n"
            "  --to-eye X,Y,Z  --to-look X,Y,Z\n"
            "                         instead of the orbit, move the camera in a straight line to this\n"
            "                         eye / look point at the last frame\n");
}

static int parse_mpi_options(int argc, char **argv, mpi_options *o, bool *help) {
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = NULL;
#define VALUE()                                                                \
    do {                                                                       \
        if (!(v = cli_flag_value(CMD, argc, argv, &i))) return CLI_EXIT_USAGE; \
    } while (0)
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            *help = true;
            return CLI_EXIT_OK;
        } else if (strcmp(a, "--mpi") == 0) {
        } else if (strcmp(a, "--mpi-bcast") == 0) {
            o->bcast = true;
        } else if (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0) {
            VALUE();
            o->output = v;
        } else if (strcmp(a, "--width") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 16384, &o->width)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--height") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 16384, &o->height)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--spp") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 65536, &o->spp)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--max-depth") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 0, 64, &o->max_depth)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--threads") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 0, CLI_MAX_THREADS, &o->threads)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--isa") == 0) {
            VALUE();
            if (!cli_parse_isa(CMD, a, v, &o->isa)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--packet") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 4, 32, &o->packet) || (o->packet & (o->packet - 1)) != 0) {
                fprintf(stderr, "raypack render: --packet expects 4, 8, 16 or 32, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--integrator") == 0) {
            VALUE();
            if (strcmp(v, "eyelight") == 0) o->integrator = RP_INTEGRATOR_EYELIGHT;
            else if (strcmp(v, "whitted") == 0) o->integrator = RP_INTEGRATOR_WHITTED;
            else {
                fprintf(stderr, "raypack render: --integrator expects eyelight or whitted, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--eye") == 0 || strcmp(a, "--look") == 0 || strcmp(a, "--up") == 0 ||
                   strcmp(a, "--to-eye") == 0 || strcmp(a, "--to-look") == 0) {
            VALUE();
            float *dst = a[2] == 'e' ? o->eye : a[2] == 'l' ? o->look : a[2] == 'u' ? o->up
                         : a[5] == 'e' ? o->to_eye : o->to_look;
            bool *has = a[2] == 'e' ? &o->has_eye : a[2] == 'l' ? &o->has_look : a[2] == 'u' ? &o->has_up
                        : a[5] == 'e' ? &o->has_to_eye : &o->has_to_look;
            if (!cli_parse_vec3(CMD, a, v, dst)) return CLI_EXIT_USAGE;
            *has = true;
        } else if (strcmp(a, "--fov") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 180.0, true, &o->fov)) return CLI_EXIT_USAGE;
            o->has_fov = true;
        } else if (strcmp(a, "--frames") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 1, 100000, &o->frames)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--orbit") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, -36000.0, 36000.0, false, &o->orbit)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--mpi-tile") == 0) {
            VALUE();
            if (!cli_parse_int(CMD, a, v, 16, 1024, &o->tile)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--mpi-compress") == 0) {
            VALUE();
            if (strcmp(v, "fast") == 0) o->raw_planes = 3;
            else if (strcmp(v, "small") == 0) o->raw_planes = 2;
            else {
                fprintf(stderr, "raypack render: --mpi-compress expects fast or small, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--mpi-timeout") == 0) {
            VALUE();
            if (!cli_parse_float(CMD, a, v, 0.0, 86400.0, true, &o->timeout_s)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--quiet") == 0 || strcmp(a, "-q") == 0) {
            o->quiet = true;
        } else if (a[0] == '-' && a[1] != '\0') {
            fprintf(stderr, "raypack render: unknown option '%s' with --mpi (see raypack render --mpi --help)\n", a);
            return CLI_EXIT_USAGE;
        } else if (!o->scene) {
            o->scene = a;
        } else {
            fprintf(stderr, "raypack render: expected one SCENE, got '%s' and '%s'\n", o->scene, a);
            return CLI_EXIT_USAGE;
        }
#undef VALUE
    }
    const char *dot = strrchr(o->output, '.');
    if (!dot || (strcasecmp(dot, ".png") != 0 && strcasecmp(dot, ".pfm") != 0 && strcasecmp(dot, ".ppm") != 0)) {
        fprintf(stderr, "raypack render: -o expects a file ending in .png, .pfm or .ppm, got '%s'\n", o->output);
        return CLI_EXIT_USAGE;
    }
    return CLI_EXIT_OK;
}

/* ---- the scene on every rank ---- */

typedef struct rank_scene {
    rp_scene_data data;
    bool builtin;
    rp_device *device;
    rp_render_scene *scene;
} rank_scene;

static void rank_scene_free(rank_scene *rs) {
    rp_render_scene_release(rs->scene);
    if (rs->device) rp_device_release(rs->device);
    if (rs->builtin) rp_default_scene_free(&rs->data);
    else rp_scene_data_free(&rs->data);
    memset(rs, 0, sizeof *rs);
}

/* Loads (or takes) the data and commits a render scene; false with a message in err. */
static bool rank_scene_build(rank_scene *rs, const mpi_options *o, int threads, char *err, size_t err_size) {
    rs->device = cli_device_new(CMD, threads, o->isa);
    if (!rs->device) {
        snprintf(err, err_size, "cannot create the device (--threads %d, --isa)", threads);
        return false;
    }
    rs->scene = rp_render_scene_new(rs->device, &rs->data, NULL, err, err_size);
    return rs->scene != NULL;
}

static bool rank_scene_load(rank_scene *rs, const char *path, char *err, size_t err_size) {
    if (!path) {
        rs->builtin = true;
        if (rp_default_scene(&rs->data)) return true;
        snprintf(err, err_size, "out of memory building the default scene");
        return false;
    }
    FILE *probe = fopen(path, "rb");
    if (!probe) {
        snprintf(err, err_size, "cannot open scene %s: %s", path, strerror(errno));
        return false;
    }
    fclose(probe);
    if (rp_scene_data_load(path, &rs->data, err, err_size)) return true;
    if (!err[0]) snprintf(err, err_size, "cannot load the scene %s", path);
    return false;
}

/* ---- rendering a tile (clients, and rank 0 alone) ---- */

typedef struct tile_worker {
    float *frame;        /* width * height * 3: rp_render writes the region in place */
    int width, height;
    float *tile;         /* the region's floats, contiguous */
    uint8_t *scratch, *packed;
    size_t tile_cap, packed_cap;
    wire_codec *codec;
    double render_cpu_ms;  /* of the last tile */
} tile_worker;

static rp_render_desc job_desc(const job_msg *j) {
    return (rp_render_desc){.width = j->width, .height = j->height, .spp = j->spp,
                            .integrator = (rp_integrator_type)j->integrator, .max_depth = j->max_depth,
                            .camera = &j->camera, .packet = j->packet,
                            .region = {j->region[0], j->region[1], j->region[2], j->region[3]}};
}

/* Renders job's region and leaves its floats in w->tile (row by row); false when out of memory. */
static bool tile_render(tile_worker *w, rp_render_scene *scene, const job_msg *j, rp_render_stats *st) {
    if (w->width != j->width || w->height != j->height) {
        free(w->frame);
        w->frame = malloc((size_t)j->width * (size_t)j->height * 3 * sizeof(float));
        w->width = j->width;
        w->height = j->height;
        if (!w->frame) return false;
    }
    int tw = j->region[2] - j->region[0], th = j->region[3] - j->region[1];
    size_t n = (size_t)tw * (size_t)th * 3;
    if (n > w->tile_cap) {
        free(w->tile);
        free(w->scratch);
        free(w->packed);
        w->tile_cap = n;
        w->packed_cap = wire_tile_bound(n);
        w->tile = malloc(n * sizeof(float));
        w->scratch = malloc(n * sizeof(float));
        w->packed = malloc(w->packed_cap);
        if (!w->codec) w->codec = wire_codec_new();
        if (!w->tile || !w->scratch || !w->packed || !w->codec) {
            w->tile_cap = 0;
            return false;
        }
    }
    rp_render_desc d = job_desc(j);
    double c0 = cpu_ms();
    if (!rp_render(scene, &d, w->frame, st)) return false;
    w->render_cpu_ms = cpu_ms() - c0;
    for (int y = 0; y < th; y++)
        memcpy(w->tile + (size_t)y * (size_t)tw * 3,
               w->frame + ((size_t)(j->region[1] + y) * (size_t)j->width + (size_t)j->region[0]) * 3,
               (size_t)tw * 3 * sizeof(float));
    return true;
}

static void tile_worker_free(tile_worker *w) {
    free(w->frame);
    free(w->tile);
    free(w->scratch);
    free(w->packed);
    wire_codec_free(w->codec);
}

/* ---- the client ---- */

static int run_client(const mpi_options *o, int rank, bool *no_finalize) {
    double idle_s = 4.0 * o->timeout_s; /* silence from rank 0 after which a client gives up */
    if (test_hook("STALL", rank)) {
        for (;;) sleep_us(1000000); /* a client that never answers: rank 0 must time out */
    }
    hello_msg hello = {.magic = MPIR_MAGIC, .protocol = MPIR_PROTOCOL,
                       .version = {RP_VERSION_MAJOR, RP_VERSION_MINOR, RP_VERSION_PATCH},
                       .desc_bytes = (uint32_t)sizeof(rp_render_desc), .pid = (int32_t)getpid()};
    long proto = test_hook("PROTOCOL", rank);
    if (proto) hello.protocol = (uint32_t)proto;
    gethostname(hello.host, sizeof hello.host - 1);
    if (!send_until(&hello, sizeof hello, 0, TAG_HELLO, MPI_Wtime() + idle_s)) return CLI_EXIT_FAILURE;

    rank_scene rs;
    memset(&rs, 0, sizeof rs);
    ready_msg ready = {.ok = 1};
    bool loaded;
    if (o->bcast) {
        uint64_t size = 0;
        uint8_t *buf = NULL;
        loaded = bcast_until(&size, sizeof size, MPI_Wtime() + idle_s) && (buf = malloc(size ? size : 1)) &&
                 bcast_until(buf, size, MPI_Wtime() + idle_s);
        if (!loaded) snprintf(ready.err, sizeof ready.err, "did not receive the broadcast scene");
        else loaded = wire_scene_unpack(buf, size, &rs.data, ready.err, sizeof ready.err);
        free(buf);
    } else {
        loaded = rank_scene_load(&rs, o->scene, ready.err, sizeof ready.err);
    }
    if (loaded && rank_scene_build(&rs, o, o->threads, ready.err, sizeof ready.err)) {
        ready.threads = rp_device_thread_count(rs.device);
        ready.triangles = rs.data.triangle_count;
    } else {
        ready.ok = 0;
    }
    int status = CLI_EXIT_FAILURE;
    tile_worker w = {0};
    if (!send_until(&ready, sizeof ready, 0, TAG_READY, MPI_Wtime() + idle_s)) goto done;
    if (!ready.ok) {
        /* Rank 0 reports the error and aborts the job; leaving first could let mpirun kill rank 0
         * before it has said why. */
        double until = MPI_Wtime() + idle_s;
        while (MPI_Wtime() < until) sleep_us(10000);
        goto done;
    }

    long kill_after = test_hook("KILL", rank), hang_after = test_hook("HANG", rank);
    long rendered = 0;
    uint8_t *msg = NULL;
    size_t msg_cap = 0;
    for (;;) {
        MPI_Status st;
        if (!probe_until(0, TAG_JOB, MPI_Wtime() + idle_s, &st)) {
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
            for (;;) sleep_us(1000000);
        rp_render_stats rst;
        result_msg res = {.kind = RESULT_TILE, .frame = job.frame, .tile = job.tile,
                          .region = {job.region[0], job.region[1], job.region[2], job.region[3]}};
        size_t payload = 0;
        const void *body = NULL;
        char err[256];
        if (tile_render(&w, rs.scene, &job, &rst)) {
            double c0 = cpu_ms();
            res.floats = (uint64_t)(job.region[2] - job.region[0]) * (uint64_t)(job.region[3] - job.region[1]) * 3;
            payload = wire_tile_pack(w.codec, w.tile, (size_t)res.floats, job.raw_planes, w.scratch, w.packed,
                                     w.packed_cap);
            body = w.packed;
            res.render_ms = rst.render_ms;
            res.render_cpu_ms = w.render_cpu_ms;
            /* the copy out of the frame is in render_cpu_ms's complement: count it with the packing */
            res.pack_cpu_ms = cpu_ms() - c0;
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
        if (!send_until(msg, sizeof res + payload, 0, TAG_RESULT, MPI_Wtime() + idle_s)) {
            fprintf(stderr, "raypack render: rank %d could not send a tile to rank 0 within %.1f s; giving up\n", rank,
                    idle_s);
            break;
        }
        rendered++;
    }
    free(msg);
done:
    tile_worker_free(&w);
    rank_scene_free(&rs);
    return status;
}

/* ---- the server ---- */

enum { QUEUE_AHEAD = 2 }; /* tiles a client holds: the one it renders and the one queued behind it */

typedef struct client {
    int rank;
    bool alive;
    hello_msg hello;
    int threads;
    int held;                      /* tiles issued and not returned */
    uint32_t held_tile[QUEUE_AHEAD];
    job_msg job[QUEUE_AHEAD];      /* send buffers, one per slot, live until their request completes */
    MPI_Request req[QUEUE_AHEAD];
    double last_heard;             /* MPI_Wtime of its last result, or of an issue to it while it held none */
    uint64_t tiles, bytes_in, bytes_out;          /* this frame */
    uint64_t tiles_all, bytes_in_all, bytes_out_all;
    double tile_ms_all;
} client;

enum { TILE_PENDING = 0, TILE_ISSUED = 1, TILE_DONE = 2 };

typedef struct server {
    const mpi_options *o;
    int size;
    client *clients;     /* ranks 1..size-1 at [rank - 1] */
    int width, height;
    int tiles_x, tiles_y, tiles;
    uint8_t *state;      /* per tile */
    int *owner;          /* the client that rendered each tile last frame (affinity), -1 none */
    int done;
    float *image;
    uint8_t *msg, *scratch;
    size_t msg_cap;
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

static bool issue(server *s, int c, int t) {
    client *cl = &s->clients[c];
    int slot = -1;
    for (int k = 0; k < QUEUE_AHEAD && slot < 0; k++) {
        if (cl->req[k] != MPI_REQUEST_NULL) {
            int done = 0;
            MPI_Test(&cl->req[k], &done, MPI_STATUS_IGNORE);
            if (!done) continue;
        }
        slot = k;
    }
    if (slot < 0) return false; /* both sends still in flight: try again later */
    job_msg *j = &cl->job[slot];
    *j = s->proto_job;
    j->kind = JOB_TILE;
    j->tile = (uint32_t)t;
    tile_region(s, t, j->region);
    if (MPI_Isend(j, (int)sizeof *j, MPI_BYTE, cl->rank, TAG_JOB, MPI_COMM_WORLD, &cl->req[slot]) != MPI_SUCCESS)
        return false;
    if (cl->held == 0) cl->last_heard = MPI_Wtime();
    cl->held_tile[cl->held++] = (uint32_t)t;
    cl->bytes_out += sizeof *j;
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
    s->lost_client = true;
}

/* Receives one result; false on a fatal error (message printed). */
static bool take_result(server *s, const MPI_Status *st) {
    int bytes = 0;
    MPI_Get_count(st, MPI_BYTE, &bytes);
    if ((size_t)bytes > s->msg_cap) {
        free(s->msg);
        s->msg_cap = (size_t)bytes;
        s->msg = malloc(s->msg_cap);
        if (!s->msg) {
            fprintf(stderr, "raypack render: out of memory for a %d-byte tile\n", bytes);
            return false;
        }
    }
    MPI_Recv(s->msg, bytes, MPI_BYTE, st->MPI_SOURCE, TAG_RESULT, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    int c = st->MPI_SOURCE - 1;
    client *cl = &s->clients[c];
    if (!cl->alive) return true; /* dropped as silent: its tiles were re-issued, this one is a duplicate */
    result_msg res;
    if ((size_t)bytes < sizeof res) {
        fprintf(stderr, "raypack render: rank %d sent a %d-byte result\n", cl->rank, bytes);
        return false;
    }
    memcpy(&res, s->msg, sizeof res);
    if (res.kind == RESULT_ERROR) {
        s->msg[bytes - 1] = '\0';
        fprintf(stderr, "raypack render: %s\n", (const char *)s->msg + sizeof res);
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
    cl->last_heard = MPI_Wtime();
    cl->bytes_in += (uint64_t)bytes;
    int32_t r[4];
    tile_region(s, (int)res.tile, r);
    size_t n = (size_t)(r[2] - r[0]) * (size_t)(r[3] - r[1]) * 3;
    float *px = s->tile_px;
    bool ok = res.floats == n &&
              wire_tile_unpack(s->codec, s->msg + sizeof res, (size_t)bytes - sizeof res, n, s->scratch, px);
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

/* Renders one frame with the clients; false on a fatal error. */
static bool server_frame(server *s) {
    int nc = s->size - 1;
    memset(s->state, TILE_PENDING, (size_t)s->tiles);
    s->done = 0;
    for (int c = 0; c < nc; c++) s->clients[c].tiles = s->clients[c].bytes_in = s->clients[c].bytes_out = 0;
    double timeout = s->o->timeout_s;
    long idle_us = 10;
    while (s->done < s->tiles) {
        int alive = 0;
        for (int c = 0; c < nc; c++) {
            client *cl = &s->clients[c];
            if (!cl->alive) continue;
            alive++;
            while (cl->held < QUEUE_AHEAD) {
                int t = pick_tile(s, c);
                if (t < 0 || !issue(s, c, t)) break;
            }
        }
        if (!alive) {
            fprintf(stderr, "raypack render: no render client is left (all were lost); frame %u is incomplete\n",
                    s->proto_job.frame);
            return false;
        }
        MPI_Status st;
        int flag = 0;
        MPI_Iprobe(MPI_ANY_SOURCE, TAG_RESULT, MPI_COMM_WORLD, &flag, &st);
        if (flag) {
            idle_us = 10;
            if (!take_result(s, &st)) return false;
            if (s->kill_after && s->done >= s->kill_after) raise(SIGKILL); /* the test of rank 0's death */
            continue;
        }
        double now = MPI_Wtime();
        for (int c = 0; c < nc; c++) {
            client *cl = &s->clients[c];
            if (cl->alive && cl->held > 0 && now - cl->last_heard > timeout) {
                char why[128];
                snprintf(why, sizeof why, "sent nothing for %.1f s while rendering", now - cl->last_heard);
                drop_client(s, c, why);
            }
        }
        /* Back off while nothing comes: every client holds a tile queued ahead, so a late look costs
         * no client time, and a busy rank 0 would take cores from clients on the same node. */
        sleep_us(idle_us);
        if (idle_us < 1000) idle_us *= 2;
    }
    return true;
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
static rp_camera frame_camera(const mpi_options *o, const rp_camera *base, int i) {
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

/* Handshake: every client's hello, then (with --mpi-bcast) the scene, then every client's ready. */
static bool server_start(server *s, rank_scene *rs, double *scene_bytes) {
    int nc = s->size - 1;
    double deadline = MPI_Wtime() + s->o->timeout_s;
    for (int c = 0; c < nc; c++) {
        client *cl = &s->clients[c];
        MPI_Status st;
        if (!probe_until(cl->rank, TAG_HELLO, deadline, &st)) {
            fprintf(stderr, "raypack render: rank %d did not answer within %.1f s (--mpi-timeout): is it running "
                            "raypack render --mpi?\n", cl->rank, s->o->timeout_s);
            return false;
        }
        int bytes = 0;
        MPI_Get_count(&st, MPI_BYTE, &bytes);
        hello_msg h;
        memset(&h, 0, sizeof h);
        MPI_Recv(&h, (int)sizeof h, MPI_BYTE, cl->rank, TAG_HELLO, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        h.host[sizeof h.host - 1] = '\0';
        if (bytes != (int)sizeof h || h.magic != MPIR_MAGIC) {
            fprintf(stderr, "raypack render: rank %d is not a raypack render client (its first message: %d bytes)\n",
                    cl->rank, bytes);
            return false;
        }
        if (h.protocol != MPIR_PROTOCOL || h.version[0] != RP_VERSION_MAJOR || h.version[1] != RP_VERSION_MINOR ||
            h.version[2] != RP_VERSION_PATCH || h.desc_bytes != sizeof(rp_render_desc)) {
            fprintf(stderr, "raypack render: rank %d (pid %d on %s) runs raypack %d.%d.%d with MPI protocol %u "
                            "(render desc %u bytes); rank 0 runs %d.%d.%d with protocol %u (%zu bytes): run the "
                            "same build on every rank\n",
                    cl->rank, h.pid, h.host, h.version[0], h.version[1], h.version[2], h.protocol, h.desc_bytes,
                    RP_VERSION_MAJOR, RP_VERSION_MINOR, RP_VERSION_PATCH, MPIR_PROTOCOL, sizeof(rp_render_desc));
            return false;
        }
        cl->hello = h;
    }
    if (s->o->bcast) {
        uint8_t *buf = NULL;
        size_t n = 0;
        if (!wire_scene_pack(&rs->data, &buf, &n)) {
            fprintf(stderr, "raypack render: out of memory packing the scene\n");
            return false;
        }
        uint64_t size = n;
        bool ok = bcast_until(&size, sizeof size, MPI_Wtime() + s->o->timeout_s) &&
                  bcast_until(buf, n, MPI_Wtime() + s->o->timeout_s + (double)n / 1e8);
        free(buf);
        if (!ok) {
            fprintf(stderr, "raypack render: broadcasting the scene (%zu bytes) did not finish within %.1f s\n", n,
                    s->o->timeout_s);
            return false;
        }
        *scene_bytes = (double)n;
    }
    deadline = MPI_Wtime() + s->o->timeout_s;
    for (int c = 0; c < nc; c++) {
        client *cl = &s->clients[c];
        MPI_Status st;
        if (!probe_until(cl->rank, TAG_READY, deadline, &st)) {
            fprintf(stderr, "raypack render: rank %d (pid %d on %s) did not report its scene ready within %.1f s "
                            "(--mpi-timeout)\n", cl->rank, cl->hello.pid, cl->hello.host, s->o->timeout_s);
            return false;
        }
        ready_msg r;
        MPI_Recv(&r, (int)sizeof r, MPI_BYTE, cl->rank, TAG_READY, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        r.err[sizeof r.err - 1] = '\0';
        if (!r.ok) {
            fprintf(stderr, "raypack render: rank %d (pid %d on %s) has no scene: %s\n", cl->rank, cl->hello.pid,
                    cl->hello.host, r.err);
            return false;
        }
        if (r.triangles != rs->data.triangle_count) {
            fprintf(stderr, "raypack render: rank %d loaded %llu triangles from %s, rank 0 %zu: not the same scene\n",
                    cl->rank, (unsigned long long)r.triangles, s->o->scene ? s->o->scene : "(built-in room)",
                    rs->data.triangle_count);
            return false;
        }
        cl->threads = r.threads;
        cl->alive = true;
    }
    return true;
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
            send_until(&q, sizeof q, cl->rank, TAG_JOB, MPI_Wtime() + s->o->timeout_s);
        } else if (strcmp(cl->hello.host, host) == 0 && cl->hello.pid > 1) {
            kill((pid_t)cl->hello.pid, SIGKILL);
        } else {
            local = false;
        }
    }
    return local;
}

/* run_server's results beyond the exit statuses: every frame written, but a client was lost (and
 * any lost one still running was on this host and is killed, or was elsewhere). */
enum { SERVER_LOST_LOCAL = -1, SERVER_LOST_REMOTE = -2 };

static int run_server(const mpi_options *o, int size) {
    double t0 = cli_now_ms();
    int status = CLI_EXIT_FAILURE;
    server s;
    memset(&s, 0, sizeof s);
    s.o = o;
    s.size = size;
    s.kill_after = test_hook("KILL", 0);
    rank_scene rs;
    memset(&rs, 0, sizeof rs);
    tile_worker w = {0};
    char err[512] = "";
    /* With clients rank 0 only hands out tiles: one thread, so it does not take their cores. */
    if (!rank_scene_load(&rs, o->scene, err, sizeof err) || !rank_scene_build(&rs, o, size > 1 ? 1 : o->threads, err, sizeof err)) {
        fprintf(stderr, "%s%s\n", strstr(err, "error:") ? "" : "raypack render: ", err);
        return CLI_EXIT_FAILURE;
    }
    double load_ms = cli_now_ms() - t0;

    rp_camera cam = rp_render_scene_default_camera(rs.scene);
    if (o->has_eye) memcpy(cam.pinhole.eye, o->eye, sizeof o->eye);
    if (o->has_look) memcpy(cam.pinhole.look, o->look, sizeof o->look);
    if (o->has_up) memcpy(cam.pinhole.up, o->up, sizeof o->up);
    if (o->has_fov) cam.pinhole.fov_deg = o->fov;
    /* image size: the rule of `raypack render` */
    int sw = rs.data.camera.width > 0 ? rs.data.camera.width : 512;
    int sh = rs.data.camera.height > 0 ? rs.data.camera.height : 512;
    int wd = o->width, ht = o->height;
    if (!wd && !ht) {
        wd = sw;
        ht = sh;
    } else if (!ht) {
        ht = (int)fmax(1.0, floor((double)wd * sh / sw + 0.5));
    } else if (!wd) {
        wd = (int)fmax(1.0, floor((double)ht * sw / sh + 0.5));
    }
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
    s.codec = wire_codec_new();
    s.tile_px = malloc((size_t)o->tile * (size_t)o->tile * 3 * sizeof(float));
    if (!s.state || !s.owner || !s.image || !s.scratch || !s.clients || !s.codec || !s.tile_px) {
        fprintf(stderr, "raypack render: out of memory for a %dx%d image\n", wd, ht);
        goto done;
    }
    for (int t = 0; t < s.tiles; t++) s.owner[t] = -1;
    for (int c = 0; c < size - 1; c++) {
        s.clients[c].rank = c + 1;
        for (int k = 0; k < QUEUE_AHEAD; k++) s.clients[c].req[k] = MPI_REQUEST_NULL;
    }
    double scene_bytes = 0.0;
    if (size > 1 && !server_start(&s, &rs, &scene_bytes)) goto done;
    if (!o->quiet) {
        printf("mpi      %d ranks: rank 0 serves %d tiles of %dx%d per frame (%dx%d image) to %d client%s", size,
               s.tiles, o->tile, o->tile, wd, ht, size - 1, size == 2 ? "" : "s");
        if (size == 1) printf(" (none: rank 0 renders alone)");
        printf("; scene %s%s, load+build %.1f ms", o->bcast && size > 1 ? "broadcast" : "loaded by every rank",
               scene_bytes > 0.0 ? "" : "", load_ms);
        if (scene_bytes > 0.0) printf(", %.2f MiB sent", scene_bytes / 1048576.0);
        printf("\n");
        for (int c = 0; c < size - 1; c++)
            printf("client   rank %d: pid %d on %s, %d threads\n", s.clients[c].rank, s.clients[c].hello.pid,
                   s.clients[c].hello.host, s.clients[c].threads);
        fflush(stdout); /* who the clients are, before the frames: a supervisor (or the kill test) reads it */
    }
    int frames = o->frames > 0 ? o->frames : 1;
    double total_ms = 0.0;
    for (int f = 0; f < frames; f++) {
        rp_camera fc = frame_camera(o, &cam, f);
        s.proto_job = (job_msg){.frame = (uint32_t)f, .width = wd, .height = ht, .spp = o->spp,
                                .integrator = (int32_t)o->integrator, .packet = o->packet, .camera = fc,
                                .raw_planes = o->raw_planes,
                                /* rp_render_desc: 0 is the default depth (5), negative is none */
                                .max_depth = o->max_depth < 0 ? 0 : (o->max_depth == 0 ? -1 : o->max_depth)};
        double f0 = cli_now_ms(), c0 = cpu_ms();
        s.render_cpu_ms = s.pack_cpu_ms = 0.0;
        if (size == 1) {
            memset(s.state, TILE_PENDING, (size_t)s.tiles);
            for (int t = 0; t < s.tiles; t++) {
                job_msg j = s.proto_job;
                j.tile = (uint32_t)t;
                tile_region(&s, t, j.region);
                rp_render_stats rst;
                if (!tile_render(&w, rs.scene, &j, &rst)) {
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
        double frame_ms = cli_now_ms() - f0, server_cpu_ms = cpu_ms() - c0;
        total_ms += frame_ms;
        char path[1100];
        frame_path(o->output, frames, f, path, sizeof path);
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
            printf("frame    %d: %s, %.1f ms, received %.1f KiB (%.2f of the raw floats), sent %.1f KiB; camera "
                   "eye %.9g,%.9g,%.9g look %.9g,%.9g,%.9g up %.9g,%.9g,%.9g fov %.9g\n",
                   f, path, frame_ms, (double)in / 1024.0,
                   (double)in / ((double)wd * ht * 3 * sizeof(float)), (double)out / 1024.0, fc.pinhole.eye[0],
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
                    printf(" rank %d %.1f%%%s", s.clients[c].rank, 100.0 * (double)s.clients[c].tiles / s.tiles,
                           s.clients[c].alive ? "" : " (lost)");
                printf("\n");
            }
        }
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
    tile_worker_free(&w);
    free(s.state);
    free(s.owner);
    free(s.image);
    free(s.scratch);
    free(s.msg);
    free(s.clients);
    free(s.tile_px);
    wire_codec_free(s.codec);
    rank_scene_free(&rs);
    if (s.lost_client && status == CLI_EXIT_OK) return all_local ? SERVER_LOST_LOCAL : SERVER_LOST_REMOTE;
    return status;
}

int cli_render_mpi(int argc, char **argv) {
    mpi_options o = {.output = "raypack.png", .max_depth = -1, .integrator = RP_INTEGRATOR_WHITTED, .packet = 16,
                     .frames = 1, .orbit = 360.0f, .tile = 64, .timeout_s = 10.0f, .raw_planes = 3};
    bool help = false;
    int rc = parse_mpi_options(argc, argv, &o, &help);
    if (rc != CLI_EXIT_OK || help) {
        if (help) mpi_usage(stdout);
        return rc;
    }
    int provided = 0;
    if (MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS) {
        fprintf(stderr, "raypack render: MPI_Init failed\n");
        return CLI_EXIT_FAILURE;
    }
    /* Errors come back as codes: a dead peer must not take this rank down inside MPI. */
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    int rank = 0, size = 1;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
    int status;
    if (rank == 0) {
        status = run_server(&o, size);
        if (status == SERVER_LOST_LOCAL || status == SERVER_LOST_REMOTE) {
            /* A client was lost: MPI_Finalize would wait for it forever. Every frame is written and
             * the others have left; a lost client elsewhere may still hang, which only MPI_Abort
             * stops (exit status 0 all the same). */
            fflush(stdout);
            fflush(stderr);
            if (status == SERVER_LOST_REMOTE) MPI_Abort(MPI_COMM_WORLD, 0);
            _exit(CLI_EXIT_OK);
        }
        if (status != CLI_EXIT_OK) {
            /* Clients may be waiting in a handshake that will never finish: stop them all. */
            fflush(stdout);
            fflush(stderr);
            MPI_Abort(MPI_COMM_WORLD, status);
            return status;
        }
    } else {
        bool no_finalize = false;
        status = run_client(&o, rank, &no_finalize);
        if (status != CLI_EXIT_OK || no_finalize) {
            /* the server reports what went wrong (or is gone); leave without the collective finalize */
            fflush(stderr);
            _exit(status);
        }
    }
    MPI_Finalize();
    return status;
}
