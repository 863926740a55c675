/* A rank's scene (loaded, or received with --mpi-bcast) and the rendering of one tile: rp_render
 * with desc.region into a frame-sized buffer, the region copied out for packing. */
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

void mpir_scene_free(mpir_scene *rs) {
    rp_render_scene_release(rs->scene);
    if (rs->device) rp_device_release(rs->device);
    if (rs->builtin) rp_default_scene_free(&rs->data);
    else rp_scene_data_free(&rs->data);
    memset(rs, 0, sizeof *rs);
}

/* Loads (or takes) the data and commits a render scene; false with a message in err. */
bool mpir_scene_build(mpir_scene *rs, const mpir_options *o, int threads, char *err, size_t err_size) {
    rs->device = cli_device_new(MPIR_CMD, threads, o->isa);
    if (!rs->device) {
        snprintf(err, err_size, "cannot create the device (--threads %d, --isa)", threads);
        return false;
    }
    rp_render_scene_desc sd = {.environment = o->env, .medium = o->vol.medium};
    if (o->has_env_scale) memcpy(sd.environment_scale, o->env_scale, sizeof o->env_scale);
    rs->scene = rp_render_scene_new(rs->device, &rs->data, &sd, err, err_size);
    return rs->scene != NULL;
}

bool mpir_scene_frame(mpir_scene *rs, float time, char *err, size_t err_size) {
    if (!rs->data.animation) return true;
    if (rp_render_scene_set_time(rs->scene, &rs->data, time, &rs->update)) return true;
    snprintf(err, err_size, "moving the animated scene to time %.9g failed (out of memory?)", (double)time);
    return false;
}

/* --volume, --volume-fit and --medium-box on the loaded data (before a broadcast, which then
 * carries the volume). */
static bool add_box(mpir_scene *rs, const mpir_options *o, char *err, size_t err_size) {
    return cli_apply_medium(&o->vol, &rs->data, err, err_size);
}

bool mpir_scene_load(mpir_scene *rs, const mpir_options *o, bool warn, char *err, size_t err_size) {
    const char *path = o->scene;
    if (!path) {
        rs->builtin = true;
        if (rp_default_scene(&rs->data)) return add_box(rs, o, err, err_size);
        snprintf(err, err_size, "out of memory building the default scene");
        return false;
    }
    FILE *probe = fopen(path, "rb");
    if (!probe) {
        snprintf(err, err_size, "cannot open scene %s: %s", path, strerror(errno));
        return false;
    }
    fclose(probe);
    rp_scene_load_desc ld;
    rp_scene_load_desc_defaults(&ld);
    ld.volume_grid = o->vol.vdb_grid;
    if (warn) ld.warning = cli_load_warning; /* the loader's warnings (file:line), once: rank 0's */
    if (rp_scene_data_load_ex(path, &ld, &rs->data, err, err_size))
        return add_box(rs, o, err, err_size);
    if (!err[0]) snprintf(err, err_size, "cannot load the scene %s", path);
    return false;
}

/* ---- rendering a tile (clients, and rank 0 alone) ---- */


static rp_render_desc job_desc(const job_msg *j) {
    return (rp_render_desc){.width = j->width, .height = j->height, .spp = j->spp,
                            .integrator = (rp_integrator_type)j->integrator, .max_depth = j->max_depth,
                            .camera = &j->camera, .packet = j->packet, .ir = j->ir, .ao_distance = j->ao_distance,
                            .region = {j->region[0], j->region[1], j->region[2], j->region[3]}};
}

/* Renders job's region and leaves its floats in w->tile (row by row); false when out of memory. */
bool mpir_tile_render(mpir_tile_worker *w, rp_render_scene *scene, const job_msg *j, rp_render_stats *st) {
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
    double c0 = mpir_cpu_ms();
    if (!rp_render(scene, &d, w->frame, st)) return false;
    w->render_cpu_ms = mpir_cpu_ms() - c0;
    for (int y = 0; y < th; y++)
        memcpy(w->tile + (size_t)y * (size_t)tw * 3,
               w->frame + ((size_t)(j->region[1] + y) * (size_t)j->width + (size_t)j->region[0]) * 3,
               (size_t)tw * 3 * sizeof(float));
    return true;
}

void mpir_tile_worker_free(mpir_tile_worker *w) {
    free(w->frame);
    free(w->tile);
    free(w->scratch);
    free(w->packed);
    wire_codec_free(w->codec);
}
