/* `raypack`: the command line front end (render, info, bench). */
#include "cli.h"

#include <signal.h>
#include <stdio.h>
#include <string.h>

#include "raypack.h"
#ifdef RP_HAVE_VIEWER
#include "../viewer/viewer.h"
#endif

static void usage(FILE *out) {
    fprintf(out,
            "usage: raypack COMMAND [ARGS]\n"
            "\n"
            "commands:\n"
            "  render [SCENE]   render a scene (the built-in room without SCENE) to an image\n"
            "  info SCENE       what a scene holds and how its BVH looks\n"
            "  bench [SCENE]    measure ray throughput\n"
            "  animate SCENE    render an animated scene's frames (BART AFF), fps with updates\n"
            "  view [SCENE]     look around in a scene in a window (SDL2)\n"
            "\n"
            "`raypack COMMAND --help` describes a command's options.\n");
}

int main(int argc, char **argv) {
    if (argc < 2) {
        usage(stderr);
        return CLI_EXIT_USAGE;
    }
    /* A write past a file-size limit fails with EFBIG (and the output keeps its old content, see
     * rp_atomic_open) instead of killing the process half-way through. */
    signal(SIGXFSZ, SIG_IGN);
    const char *cmd = argv[1];
    /* loads and builds fault in thousands of fresh pages: 2 MiB ones cost a fraction (heap.c);
     * for the commands that allocate nothing much it is address space only */
    cli_heap_hugepages((size_t)256 << 20);
    if (strcmp(cmd, "render") == 0) return cli_render(argc - 1, argv + 1);
    if (strcmp(cmd, "info") == 0) return cli_info(argc - 1, argv + 1);
    if (strcmp(cmd, "bench") == 0) return cli_bench(argc - 1, argv + 1);
    if (strcmp(cmd, "animate") == 0) return cli_animate(argc - 1, argv + 1);
    if (strcmp(cmd, "view") == 0) {
#ifdef RP_HAVE_VIEWER
        return cli_view(argc - 1, argv + 1);
#else
        fprintf(stderr, "raypack view: this raypack was built without SDL2 (apt install libsdl2-dev, rebuild)\n");
        return CLI_EXIT_FAILURE;
#endif
    }
    if (strcmp(cmd, "--help") == 0 || strcmp(cmd, "-h") == 0 || strcmp(cmd, "help") == 0) {
        usage(stdout);
        return CLI_EXIT_OK;
    }
    if (strcmp(cmd, "--version") == 0) {
        printf("raypack %d.%d.%d\n", RP_VERSION_MAJOR, RP_VERSION_MINOR, RP_VERSION_PATCH);
        return CLI_EXIT_OK;
    }
    fprintf(stderr, "raypack: unknown command '%s' (expected render, info, bench, animate or view)\n", cmd);
    usage(stderr);
    return CLI_EXIT_USAGE;
}
