/* Helpers shared by the subcommands: flag values, numbers, clock. */
#include "cli.h"

#include <errno.h>
#include <libgen.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

double cli_now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

double cli_cpu_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

const char *cli_flag_value(const char *cmd, int argc, char **argv, int *i) {
    if (*i + 1 >= argc) {
        fprintf(stderr, "raypack %s: %s expects a value\n", cmd, argv[*i]);
        return NULL;
    }
    *i += 1;
    return argv[*i];
}

bool cli_parse_int(const char *cmd, const char *flag, const char *text, long lo, long hi, int *out) {
    char *end;
    errno = 0;
    long v = strtol(text, &end, 10);
    if (end == text || *end != '\0' || errno == ERANGE || v < lo || v > hi) {
        fprintf(stderr, "raypack %s: %s expects an integer in [%ld, %ld], got '%s'\n", cmd, flag, lo, hi, text);
        return false;
    }
    *out = (int)v;
    return true;
}

bool cli_parse_float(const char *cmd, const char *flag, const char *text, double lo, double hi, bool open,
                     float *out) {
    char *end;
    errno = 0;
    double v = strtod(text, &end);
    bool in = open ? (v > lo && v < hi) : (v >= lo && v <= hi);
    if (end == text || *end != '\0' || errno == ERANGE || !isfinite(v) || !in) {
        fprintf(stderr, "raypack %s: %s expects a number in %c%g, %g%c, got '%s'\n", cmd, flag, open ? '(' : '[',
                lo, hi, open ? ')' : ']', text);
        return false;
    }
    *out = (float)v;
    return true;
}

int cli_parse_list(const char *cmd, const char *flag, const char *text, uint32_t *out, int max) {
    int n = 0;
    const char *p = text;
    for (;;) {
        char *end;
        errno = 0;
        long v = strtol(p, &end, 10);
        if (end == p || v < 0 || v > 1000000 || errno || (*end != ',' && *end != '\0') || n >= max) {
            fprintf(stderr, "raypack %s: %s expects up to %d indices like 0,2,3, got '%s'\n", cmd, flag, max, text);
            return -1;
        }
        out[n++] = (uint32_t)v;
        if (*end == '\0') return n;
        p = end + 1;
    }
}

bool cli_parse_vec3(const char *cmd, const char *flag, const char *text, float out[3]) {
    const char *p = text;
    for (int k = 0; k < 3; k++) {
        char *end;
        errno = 0;
        double v = strtod(p, &end);
        if (end == p || errno == ERANGE || !isfinite(v) || fabs(v) > 1e30 || *end != (k < 2 ? ',' : '\0')) {
            fprintf(stderr, "raypack %s: %s expects three numbers x,y,z, got '%s'\n", cmd, flag, text);
            return false;
        }
        out[k] = (float)v;
        p = end + 1;
    }
    return true;
}

static const struct {
    const char *name;
    int code;
} isa_names[] = {{"auto", 0}, {"scalar", 1}, {"sse", 4}, {"avx2", 8}, {"avx512", 16}};

bool cli_parse_isa(const char *cmd, const char *flag, const char *text, int *out) {
    for (size_t i = 0; i < sizeof isa_names / sizeof isa_names[0]; i++)
        if (strcmp(text, isa_names[i].name) == 0) {
            *out = isa_names[i].code;
            return true;
        }
    fprintf(stderr, "raypack %s: %s expects auto, scalar, sse, avx2 or avx512, got '%s'\n", cmd, flag, text);
    return false;
}

bool cli_parse_accel(const char *cmd, const char *flag, const char *text, rp_accel_type *out) {
    for (int k = 0; k < RP_ACCEL_COUNT; k++)
        if (strcmp(text, rp_accel_name((rp_accel_type)k)) == 0) {
            *out = (rp_accel_type)k;
            return true;
        }
    fprintf(stderr, "raypack %s: %s expects bvh, kdtree, bih or grid, got '%s'\n", cmd, flag, text);
    return false;
}

const char *cli_isa_name(int isa) {
    for (size_t i = 0; i < sizeof isa_names / sizeof isa_names[0]; i++)
        if (isa_names[i].code == isa) return isa_names[i].name;
    return "?";
}

rp_device *cli_device_new(const char *cmd, int threads, int isa) {
    rp_device *d = rp_device_new(&(rp_device_desc){.threads = threads, .isa = isa});
    if (d) return d;
    rp_device *best = isa ? rp_device_new(&(rp_device_desc){.threads = 1}) : NULL;
    if (best && rp_device_isa(best) < isa)
        fprintf(stderr, "raypack %s: --isa %s: this CPU has up to %s\n", cmd, cli_isa_name(isa),
                cli_isa_name(rp_device_isa(best)));
    else
        fprintf(stderr, "raypack %s: cannot create the device\n", cmd);
    rp_device_release(best);
    return NULL;
}

void cli_json_traversal(FILE *f, const rp_counters_n *c) {
    static const char *const names[] = {"auto", "masked", "ranged", "partition", "span", "simd", "mlrt"};
    fputs("\"traversal\": {", f);
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        fprintf(f, "%s\"%s\": %llu", i ? ", " : "", names[i], (unsigned long long)c->traversal[i]);
    fputc('}', f);
}

/* A path's folder resolved (symbolic links, "..") plus its last name, for paths that do not exist. */
static bool canonical_missing(const char *path, char *out, size_t size) {
    const char *slash = strrchr(path, '/');
    char dir[PATH_MAX];
    if (!slash) snprintf(dir, sizeof dir, ".");
    else if (slash == path) snprintf(dir, sizeof dir, "/");
    else snprintf(dir, sizeof dir, "%.*s", (int)(slash - path), path);
    char real[PATH_MAX];
    if (!realpath(dir, real)) return false;
    int n = snprintf(out, size, "%s/%s", real, slash ? slash + 1 : path);
    return n > 0 && (size_t)n < size;
}

bool cli_same_file(const char *a, const char *b) {
    struct stat sa, sb;
    bool ea = stat(a, &sa) == 0, eb = stat(b, &sb) == 0;
    if (ea && eb) return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
    if (ea != eb) return false;
    char ca[PATH_MAX + 256], cb[PATH_MAX + 256];
    if (canonical_missing(a, ca, sizeof ca) && canonical_missing(b, cb, sizeof cb)) return strcmp(ca, cb) == 0;
    return strcmp(a, b) == 0;
}

bool cli_check_paths(const char *cmd, const cli_path *paths, int count) {
    for (int i = 0; i < count; i++) {
        if (!paths[i].path || paths[i].input) continue;
        for (int j = 0; j < count; j++) {
            if (j == i || !paths[j].path || (!paths[j].input && j > i)) continue;
            if (!cli_same_file(paths[i].path, paths[j].path)) continue;
            if (paths[j].input)
                fprintf(stderr, "raypack %s: %s %s is the input %s: it would be overwritten\n", cmd, paths[i].flag,
                        paths[i].path, paths[j].flag);
            else
                fprintf(stderr, "raypack %s: %s %s and %s %s are the same file\n", cmd, paths[j].flag,
                        paths[j].path, paths[i].flag, paths[i].path);
            return false;
        }
    }
    return true;
}

bool cli_output_writable(const char *cmd, const char *path) {
    struct stat st;
    if (stat(path, &st) == 0) {
        if (S_ISDIR(st.st_mode)) {
            fprintf(stderr, "raypack %s: cannot write %s: it is a directory\n", cmd, path);
            return false;
        }
        if (access(path, W_OK) != 0) {
            fprintf(stderr, "raypack %s: cannot write %s: %s\n", cmd, path, strerror(errno));
            return false;
        }
        return true;
    }
    char *copy = strdup(path);
    if (!copy) return true;
    const char *dir = dirname(copy);
    bool ok = true;
    if (stat(dir, &st) != 0 || !S_ISDIR(st.st_mode)) {
        fprintf(stderr, "raypack %s: cannot write %s: folder %s does not exist\n", cmd, path, dir);
        ok = false;
    } else if (access(dir, W_OK) != 0) {
        fprintf(stderr, "raypack %s: cannot write %s: folder %s: %s\n", cmd, path, dir, strerror(errno));
        ok = false;
    }
    free(copy);
    return ok;
}

bool cli_scene_in_reach(const char *cmd, const char *path, rp_render_scene *scene, const rp_camera *cam) {
    return cli_core_in_reach(cmd, path, rp_render_scene_core(scene), cam->pinhole.eye);
}

bool cli_core_in_reach(const char *cmd, const char *path, rp_scene *scene, const float eye[3]) {
    rp_bounds b;
    rp_scene_get_bounds(scene, &b);
    if (!(b.lower_x <= b.upper_x && b.lower_y <= b.upper_y && b.lower_z <= b.upper_z)) return true; /* nothing */
    const float lo[3] = {b.lower_x, b.lower_y, b.lower_z}, hi[3] = {b.upper_x, b.upper_y, b.upper_z};
    double reach = 0.0;
    for (int k = 0; k < 3; k++)
        reach = fmax(reach, fmax((double)hi[k] - lo[k], fmax(fabs((double)hi[k] - eye[k]), fabs((double)lo[k] - eye[k]))));
    if (reach <= CLI_MAX_REACH) return true;
    fprintf(stderr, "raypack %s: %s: error: the scene and the eye span %g: past %g the float shading and intersection "
                    "tests overflow (scale the scene down)\n", cmd, path ? path : "(built-in scene)", reach, CLI_MAX_REACH);
    return false;
}

bool cli_scene_readable(const char *cmd, const char *path) {
    struct stat st;
    int e = stat(path, &st) != 0 ? errno : S_ISDIR(st.st_mode) ? EISDIR : access(path, R_OK) != 0 ? errno : 0;
    if (e) fprintf(stderr, "raypack %s: cannot open scene %s: %s\n", cmd, path, strerror(e));
    return e == 0;
}

void cli_load_warning(void *user, const char *message) {
    (void)user;
    fprintf(stderr, "%s\n", message);
}

bool cli_has_cutouts(const rp_scene_data *data) {
    for (size_t i = 0; i < data->material_count; i++)
        if (data->materials[i].alpha_mode != RP_ALPHA_OPAQUE) return true;
    return false;
}

const char *cli_camera_problem(const float eye[3], const float look[3], const float up[3]) {
    /* in float, as the renderer forms the frame (DESIGN.md: f = normalize(look - eye), r = f x up) */
    float d[3] = {look[0] - eye[0], look[1] - eye[1], look[2] - eye[2]};
    for (int k = 0; k < 3; k++)
        if (!isfinite(eye[k]) || !isfinite(look[k]) || !isfinite(up[k]) || !isfinite(d[k])) return "not finite";
    double dd = (double)d[0] * d[0] + (double)d[1] * d[1] + (double)d[2] * d[2];
    double uu = (double)up[0] * up[0] + (double)up[1] * up[1] + (double)up[2] * up[2];
    if (!(dd > 0.0)) return "the eye is the look-at point (no view direction)";
    if (!(uu > 0.0)) return "the up vector is zero";
    double c[3] = {(double)d[1] * up[2] - (double)d[2] * up[1], (double)d[2] * up[0] - (double)d[0] * up[2],
                   (double)d[0] * up[1] - (double)d[1] * up[0]};
    double cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
    /* sin^2 of the angle between view and up under 1e-10: the image's right vector is noise */
    if (!(cc > 1e-10 * dd * uu)) return "the up vector is parallel to the view direction";
    return NULL;
}

int cli_camera_flags_check(const char *cmd, const float *eye, const float *look, const float *up) {
    if (eye && look) {
        /* whether some up could make a frame, then the given one */
        static const float any_up[3] = {0.0f, 1.0f, 0.0f}, other_up[3] = {1.0f, 0.0f, 0.0f};
        const char *why = cli_camera_problem(eye, look, any_up);
        if (why && cli_camera_problem(eye, look, other_up)) {
            fprintf(stderr, "raypack %s: --eye and --look: %s\n", cmd, why);
            return CLI_EXIT_USAGE;
        }
        if (up && (why = cli_camera_problem(eye, look, up)) != NULL) {
            fprintf(stderr, "raypack %s: --eye, --look and --up: %s\n", cmd, why);
            return CLI_EXIT_USAGE;
        }
    }
    if (up && !(up[0] != 0.0f || up[1] != 0.0f || up[2] != 0.0f)) {
        fprintf(stderr, "raypack %s: --up 0,0,0 is not a direction\n", cmd);
        return CLI_EXIT_USAGE;
    }
    return CLI_EXIT_OK;
}

int cli_camera_check(const char *cmd, const char *path, const float eye[3], const float look[3], const float up[3],
                     bool has_eye, bool has_look, bool has_up) {
    const char *why = cli_camera_problem(eye, look, up);
    if (!why) return CLI_EXIT_OK;
    /* name the flags that made it, else the scene's camera */
    char from[64] = "";
    if (has_eye) strcat(from, "--eye ");
    if (has_look) strcat(from, "--look ");
    if (has_up) strcat(from, "--up ");
    if (!from[0]) { /* the file's camera, or the one framing its bounds (past 1e38 they overflow) */
        fprintf(stderr, "raypack %s: %s: error: the scene's camera: %s\n", cmd, path ? path : "(built-in scene)", why);
        return CLI_EXIT_FAILURE;
    }
    from[strlen(from) - 1] = '\0';
    fprintf(stderr, "raypack %s: %s%s: %s\n", cmd, from, !(has_eye && has_look && has_up) ? " with the scene's camera" : "",
            why);
    return CLI_EXIT_USAGE;
}

bool cli_is_medium_flag(const char *a) {
    return strcmp(a, "--density-scale") == 0 || strcmp(a, "--albedo") == 0 || strcmp(a, "--hg-g") == 0 ||
           strcmp(a, "--medium-box") == 0 || strcmp(a, "--vdb-grid") == 0 || strcmp(a, "--volume") == 0 ||
           strcmp(a, "--volume-fit") == 0;
}

/* "X0,Y0,Z0,X1,Y1,Z1", the second corner above the first on every axis. */
static bool parse_box(const char *cmd, const char *a, const char *v, float box[6]) {
    char lo[256], hi[256];
    const char *c3 = v;
    for (int k = 0; k < 3 && c3; k++) c3 = strchr(c3 + (k ? 1 : 0), ',');
    if (!c3 || (size_t)(c3 - v) >= sizeof lo || strlen(c3 + 1) >= sizeof hi) {
        fprintf(stderr, "raypack %s: %s expects X0,Y0,Z0,X1,Y1,Z1, got '%s'\n", cmd, a, v);
        return false;
    }
    memcpy(lo, v, (size_t)(c3 - v));
    lo[c3 - v] = '\0';
    strcpy(hi, c3 + 1);
    if (!cli_parse_vec3(cmd, a, lo, box) || !cli_parse_vec3(cmd, a, hi, box + 3)) return false;
    for (int k = 0; k < 3; k++)
        if (!(box[3 + k] > box[k])) {
            fprintf(stderr, "raypack %s: %s: the second corner must be above the first on every axis, got '%s'\n", cmd, a, v);
            return false;
        }
    return true;
}

bool cli_parse_medium_flag(const char *cmd, const char *a, const char *v, cli_medium_opts *m) {
    if (strcmp(a, "--density-scale") == 0) return cli_parse_float(cmd, a, v, 0.0, 1e6, true, &m->medium.density_scale);
    if (strcmp(a, "--hg-g") == 0) return cli_parse_float(cmd, a, v, -0.99, 0.99, false, &m->medium.hg_g);
    if (strcmp(a, "--vdb-grid") == 0) {
        m->vdb_grid = v;
        return true;
    }
    if (strcmp(a, "--volume") == 0) {
        m->volume = v;
        return true;
    }
    if (strcmp(a, "--volume-fit") == 0) return (m->has_fit = parse_box(cmd, a, v, m->fit));
    if (strcmp(a, "--medium-box") == 0) return (m->has_box = parse_box(cmd, a, v, m->box));
    /* --albedo A or R,G,B */
    float al[3];
    if (strchr(v, ',')) {
        if (!cli_parse_vec3(cmd, a, v, al)) return false;
    } else {
        if (!cli_parse_float(cmd, a, v, 0.0, 1.0, false, &al[0])) return false;
        al[1] = al[2] = al[0];
    }
    for (int k = 0; k < 3; k++) {
        if (!(al[k] >= 0.0f && al[k] <= 1.0f)) {
            fprintf(stderr, "raypack %s: --albedo expects values in [0, 1], got '%s'\n", cmd, v);
            return false;
        }
        m->medium.albedo[k] = al[k] == 0.0f ? -1.0f : al[k]; /* rp_medium_desc: negative is black */
    }
    return true;
}

/* Scales v's index-to-world map uniformly and moves it so that its active voxels' world box (their
 * cells' corners) is centred in box and touches it on its tightest axis. */
static void fit_volume(rp_volume_data *v, const float box[6]) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    const float *M = v->index_to_world;
    for (int c = 0; c < 8; c++) {
        double p[3];
        for (int k = 0; k < 3; k++) p[k] = (c >> k & 1) ? v->active_max[k] + 0.5 : v->active_min[k] - 0.5;
        for (int r = 0; r < 3; r++) {
            double w = (double)M[4 * r] * p[0] + (double)M[4 * r + 1] * p[1] + (double)M[4 * r + 2] * p[2] + M[4 * r + 3];
            lo[r] = fmin(lo[r], w), hi[r] = fmax(hi[r], w);
        }
    }
    double s = INFINITY;
    for (int k = 0; k < 3; k++) s = fmin(s, (box[3 + k] - box[k]) / (hi[k] - lo[k]));
    float out[12];
    for (int r = 0; r < 3; r++) {
        double t = 0.5 * (box[r] + box[3 + r]) - s * 0.5 * (lo[r] + hi[r]);
        for (int c = 0; c < 3; c++) out[4 * r + c] = (float)(s * M[4 * r + c]);
        out[4 * r + 3] = (float)(s * M[4 * r + 3] + t);
    }
    memcpy(v->index_to_world, out, sizeof out);
}

bool cli_apply_medium(const cli_medium_opts *m, rp_scene_data *data, char *err, size_t err_size) {
    if (m->volume && m->has_box) {
        snprintf(err, err_size, "--volume and --medium-box: a scene holds one volume, give one of them");
        return false;
    }
    if (m->volume) {
        rp_scene_load_desc ld;
        rp_scene_load_desc_defaults(&ld);
        ld.volume_grid = m->vdb_grid;
        rp_scene_data vd;
        char why[512] = "";
        if (!rp_scene_data_load_ex(m->volume, &ld, &vd, why, sizeof why)) {
            snprintf(err, err_size, "--volume: %s", why[0] ? why : m->volume);
            return false;
        }
        if (!vd.volume) {
            snprintf(err, err_size, "--volume %s: the file holds no volume (a .vdb is wanted)", m->volume);
            rp_scene_data_free(&vd);
            return false;
        }
        rp_volume_data *v = vd.volume;
        vd.volume = NULL;
        rp_scene_data_free(&vd);
        rp_scene_data own = {.volume = data->volume};
        rp_scene_data_free(&own); /* the scene's own volume, if any */
        data->volume = v;
    }
    if (m->has_fit) {
        if (!data->volume || !data->volume->active_voxels) {
            snprintf(err, err_size, "--volume-fit: the scene has no volume to fit (give --volume FILE.vdb)");
            return false;
        }
        fit_volume(data->volume, m->fit);
    }
    if (m->has_box && !rp_scene_data_add_medium_box(data, m->box, m->box + 3)) {
        snprintf(err, err_size, "out of memory for --medium-box");
        return false;
    }
    return true;
}
