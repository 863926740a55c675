/* `mpirun -np N raypack render SCENE --mpi`: distributed rendering as the survey describes OpenRT's
 * cluster (Recheis, sec. 5.2; Wald et al. 2001): rank 0 is the display server, every other rank a
 * render client with the device's threads. The server cuts each frame into tiles and hands them out
 * dynamically, keeping one tile queued ahead on every client so that none waits for its next job;
 * clients send finished tiles back compressed (wire.c), and the server writes the image through the
 * same rp_image_write as `raypack render`. A pixel's value depends only on the pixel (the
 * deterministic sampler), so the image is bit-identical to the single process for any N. A BART
 * animation plays under --frames: each job carries its frame's time (`raypack animate`'s rule,
 * rp_anim_frame_time), and every rank moves its copy of the scene there (rp_render_scene_set_time)
 * before it renders the frame's first tile; --mpi-bcast sends the animation with the scene.
 *
 * Transport and faults, with Open MPI 4.1 (no ULFM): MPI starts the ranks and carries one message,
 * rank 0's TCP address and a token, to each client; scenes (--mpi-bcast), tiles and results travel
 * on one TCP connection per client (mpi_net.c), polled by rank 0, so no MPI call can leave rank 0
 * waiting on a dead peer inside Open MPI's transport. A client that dies (kill -9, a crash, its node
 * going down) closes its connection: rank 0 sees the end of stream at once (a node that vanishes
 * without a reset: silence) and hands its tiles to the others; one that stops answering is dropped
 * when it has sent nothing for --mpi-timeout seconds while it holds tiles. The frame comes out the
 * same. That needs the job to outlive the client: `mpirun --enable-recovery` (without it mpirun kills
 * every rank when one dies). MPI_Finalize would then wait for the dead rank forever, so after the
 * last frame a server that lost a client tells the others to leave without it, kills a lost client
 * that still runs on its host (one that hangs), and leaves too; a lost client on another host is
 * stopped with MPI_Abort(0) (exit status 0). The server's own death ends the job: each client sees
 * its connection close and gives up at once.
 *
 * Files: mpi_render.c (options, the entry, MPI start and end), mpi_server.c (rank 0), mpi_client.c
 * (the others), mpi_tile.c (a rank's scene, one tile's rendering), mpi_net.c (the TCP transport),
 * wire.c (the byte formats of scenes and tiles). */
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

static void mpi_usage(FILE *out) {
    fprintf(out,
            "usage: mpirun -np N raypack render [SCENE] --mpi [options]\n"
            "\n"
            "Distributed rendering: rank 0 hands image tiles to ranks 1..N-1 (each with the device's\n"
            "threads) and writes the image, identical to `raypack render`'s. With -np 1 rank 0 renders\n"
            "alone. MPI only starts the ranks and tells the clients rank 0's TCP address; tiles travel on\n"
            "one TCP connection per client. Use `mpirun --enable-recovery` so that a client's death does\n"
            "not end the job: its tiles are then rendered by the others.\n"
            "\n"
            "options (as in `raypack render`): -o FILE (.png .ppm .pfm), --width W, --height H, --spp N,\n"
            "  --integrator whitted|eyelight|direct|path|ir|ao, --max-depth N, --packet N, --threads N,\n"
            "  --isa NAME, --ir-interleave N, --ir-vpls N, --ir-filter N, --ir-clamp C, --ir-rr X,\n"
            "  --ao-distance D, --env FILE.hdr (read by every rank), --env-scale R,G,B, --exposure EV,\n"
            "  --tonemap srgb|aces,\n"
            "  --eye X,Y,Z --look X,Y,Z --up X,Y,Z --fov DEG, --density-scale S, --albedo A|R,G,B,\n"
            "  --hg-g G, --vdb-grid NAME, --medium-box X0,Y0,Z0,X1,Y1,Z1 (volumes travel with --mpi-bcast),\n"
            "  --quiet\n"
            "MPI options:\n"
            "  --mpi                  distributed rendering (needed)\n"
            "  --mpi-bcast            only rank 0 reads SCENE and sends its data to every client on its\n"
            "                         connection (else every rank loads the same path)\n"
            "  --mpi-tile N           tile side handed to a client, 16..1024 [64]\n"
            "  --mpi-compress fast|small\n"
            "                         how tiles travel: fast deflates only each float's sign and exponent\n"
            "                         byte (kitchen: 0.77 of the floats' bytes, 11 ms CPU per 1024x1024\n"
            "                         frame), small also the top mantissa byte (0.66, 41 ms) [fast]\n"
            "  --mpi-timeout S        seconds a client may stay silent while it holds tiles (then its\n"
            "                         tiles go to the others), and the limit of the start-up handshake [10]\n"
            "  --frames N             render a sequence of N frames, 1..100000, written as FILE_0000.EXT...\n"
            "                         [1]. An animated scene (BART AFF) plays its animation: frame i at\n"
            "                         `raypack animate --frames N`'s time, the camera on the scene's path\n"
            "                         (every rank moves the scene before the frame's tiles). A still scene's\n"
            "                         camera orbits the look point about the up axis\n"
            "  --anim-time T          animated scenes: every frame holds the scene at time T (as `raypack\n"
            "                         render --anim-time T`), and the camera orbits or moves as for a still one\n"
            "  --orbit DEG            degrees the eye turns over the sequence [360]\n"
            "  --to-eye X,Y,Z  --to-look X,Y,Z\n"
            "                         instead of the orbit, move the camera in a straight line to this\n"
            "                         eye / look point at the last frame\n");
}

static int parse_mpi_options(int argc, char **argv, mpir_options *o, bool *help) {
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = NULL;
#define VALUE()                                                                \
    do {                                                                       \
        if (!(v = cli_flag_value(MPIR_CMD, argc, argv, &i))) return CLI_EXIT_USAGE; \
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
            if (!cli_parse_int(MPIR_CMD, a, v, 1, 16384, &o->width)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--height") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 1, 16384, &o->height)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--spp") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 1, 65536, &o->spp)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--max-depth") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 0, 64, &o->max_depth)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--threads") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 0, CLI_MAX_THREADS, &o->threads)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--isa") == 0) {
            VALUE();
            if (!cli_parse_isa(MPIR_CMD, a, v, &o->isa)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--packet") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 4, 32, &o->packet) || (o->packet & (o->packet - 1)) != 0) {
                fprintf(stderr, "raypack render: --packet expects 4, 8, 16 or 32, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--integrator") == 0) {
            VALUE();
            static const struct { const char *name; rp_integrator_type type; } integrators[] = {
                {"whitted", RP_INTEGRATOR_WHITTED}, {"eyelight", RP_INTEGRATOR_EYELIGHT},
                {"direct", RP_INTEGRATOR_DIRECT},   {"path", RP_INTEGRATOR_PATH},
                {"ir", RP_INTEGRATOR_IR},           {"ao", RP_INTEGRATOR_AO}};
            size_t k = 0, n = sizeof integrators / sizeof integrators[0];
            while (k < n && strcmp(v, integrators[k].name) != 0) k++;
            if (k == n) {
                fprintf(stderr, "raypack render: --integrator expects whitted, eyelight, direct, path, ir or ao, got "
                                "'%s'\n", v);
                return CLI_EXIT_USAGE;
            }
            o->integrator = integrators[k].type;
        } else if (strcmp(a, "--ir-interleave") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 1, 16, &o->ir_interleave)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--ir-vpls") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 1, 4096, &o->ir_vpls)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--ir-filter") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 1, 31, &o->ir_filter)) return CLI_EXIT_USAGE;
            if (o->ir_filter % 2 == 0) {
                fprintf(stderr, "raypack render: --ir-filter expects an odd side, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (strcmp(a, "--ir-clamp") == 0) {
            VALUE();
            if (!cli_parse_float(MPIR_CMD, a, v, -1.0, 1.0, false, &o->ir_clamp)) return CLI_EXIT_USAGE;
            if (o->ir_clamp == 0.0f) o->ir_clamp = -1.0f;
        } else if (strcmp(a, "--ir-rr") == 0) {
            VALUE();
            if (!cli_parse_float(MPIR_CMD, a, v, 0.0, 16.0, false, &o->ir_rr)) return CLI_EXIT_USAGE;
            if (o->ir_rr == 0.0f) o->ir_rr = -1.0f;
        } else if (strcmp(a, "--ao-distance") == 0) {
            VALUE();
            if (!cli_parse_float(MPIR_CMD, a, v, 0.0, 1e30, true, &o->ao_distance)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--exposure") == 0) {
            VALUE();
            if (!cli_parse_float(MPIR_CMD, a, v, -64.0, 64.0, false, &o->exposure)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--tonemap") == 0) {
            VALUE();
            if (strcmp(v, "srgb") == 0) o->tonemap = RP_TONEMAP_SRGB;
            else if (strcmp(v, "aces") == 0) o->tonemap = RP_TONEMAP_ACES;
            else {
                fprintf(stderr, "raypack render: --tonemap expects srgb or aces, got '%s'\n", v);
                return CLI_EXIT_USAGE;
            }
        } else if (cli_is_medium_flag(a)) {
            VALUE();
            if (!cli_parse_medium_flag(MPIR_CMD, a, v, &o->vol)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--env") == 0) {
            VALUE();
            o->env = v;
        } else if (strcmp(a, "--env-scale") == 0) {
            VALUE();
            if (!cli_parse_vec3(MPIR_CMD, a, v, o->env_scale)) return CLI_EXIT_USAGE;
            o->has_env_scale = true;
        } else if (strcmp(a, "--eye") == 0 || strcmp(a, "--look") == 0 || strcmp(a, "--up") == 0 ||
                   strcmp(a, "--to-eye") == 0 || strcmp(a, "--to-look") == 0) {
            VALUE();
            float *dst = a[2] == 'e' ? o->eye : a[2] == 'l' ? o->look : a[2] == 'u' ? o->up
                         : a[5] == 'e' ? o->to_eye : o->to_look;
            bool *has = a[2] == 'e' ? &o->has_eye : a[2] == 'l' ? &o->has_look : a[2] == 'u' ? &o->has_up
                        : a[5] == 'e' ? &o->has_to_eye : &o->has_to_look;
            if (!cli_parse_vec3(MPIR_CMD, a, v, dst)) return CLI_EXIT_USAGE;
            *has = true;
        } else if (strcmp(a, "--fov") == 0) {
            VALUE();
            if (!cli_parse_float(MPIR_CMD, a, v, 0.0, 180.0, true, &o->fov)) return CLI_EXIT_USAGE;
            o->has_fov = true;
        } else if (strcmp(a, "--frames") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 1, 100000, &o->frames)) return CLI_EXIT_USAGE;
        } else if (strcmp(a, "--orbit") == 0) {
            VALUE();
            if (!cli_parse_float(MPIR_CMD, a, v, -36000.0, 36000.0, false, &o->orbit)) return CLI_EXIT_USAGE;
            o->has_orbit = true;
        } else if (strcmp(a, "--anim-time") == 0) {
            VALUE();
            if (!cli_parse_float(MPIR_CMD, a, v, -1e30, 1e30, true, &o->anim_time)) return CLI_EXIT_USAGE;
            o->has_anim_time = true;
        } else if (strcmp(a, "--mpi-tile") == 0) {
            VALUE();
            if (!cli_parse_int(MPIR_CMD, a, v, 16, 1024, &o->tile)) return CLI_EXIT_USAGE;
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
            if (!cli_parse_float(MPIR_CMD, a, v, 0.0, 86400.0, true, &o->timeout_s)) return CLI_EXIT_USAGE;
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
    int cam_status = cli_camera_flags_check(MPIR_CMD, o->has_eye ? o->eye : NULL, o->has_look ? o->look : NULL,
                                            o->has_up ? o->up : NULL);
    if (cam_status != CLI_EXIT_OK) return cam_status;
    const char *dot = strrchr(o->output, '.');
    if (!dot || (strcasecmp(dot, ".png") != 0 && strcasecmp(dot, ".pfm") != 0 && strcasecmp(dot, ".ppm") != 0)) {
        fprintf(stderr, "raypack render: -o expects a file ending in .png, .pfm or .ppm, got '%s'\n", o->output);
        return CLI_EXIT_USAGE;
    }
    return CLI_EXIT_OK;
}

int cli_render_mpi(int argc, char **argv) {
    mpir_options o = {.output = "raypack.png", .max_depth = -1, .integrator = RP_INTEGRATOR_WHITTED, .packet = 16,
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
        status = mpir_server_run(&o, size);
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
        status = mpir_client_run(&o, rank, &no_finalize);
        if (status != CLI_EXIT_OK || no_finalize) {
            /* the server reports what went wrong (or is gone); leave without the collective finalize */
            fflush(stderr);
            _exit(status);
        }
    }
    MPI_Finalize();
    return status;
}
