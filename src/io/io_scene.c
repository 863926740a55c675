/* rp_scene_data_load: picks the loader from the extension, runs it into a builder, then hands the
 * builder's arrays to the caller's rp_scene_data. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <sys/stat.h>
#include <time.h>

#include "io/io_internal.h"
#include "io/io_volume.h"

bool io_error(io_ctx *ctx, const char *file, uint32_t line, const char *fmt, ...) {
    if (ctx->failed) return false; /* the first error is the one that explains the others */
    ctx->failed = true;
    if (!ctx->err || ctx->err_size == 0) return false;
    int n = snprintf(ctx->err, ctx->err_size, "%s:%u: error: ", file, line);
    if (n >= 0 && (size_t)n < ctx->err_size) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(ctx->err + n, ctx->err_size - (size_t)n, fmt, ap);
        va_end(ap);
    }
    return false;
}

void io_warning(io_ctx *ctx, const char *file, uint32_t line, const char *fmt, ...) {
    if (!ctx->warning || ctx->warnings++ >= RP_LOAD_MAX_WARNINGS) return;
    char msg[IO_PATH_MAX + 512];
    int n = snprintf(msg, sizeof msg, "%s:%u: warning: ", file, line);
    if (n >= 0 && (size_t)n < sizeof msg) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(msg + n, sizeof msg - (size_t)n, fmt, ap);
        va_end(ap);
    }
    ctx->warning(ctx->warning_user, msg);
}

bool io_reserve(void **p, size_t *cap, size_t need, size_t elem) {
    if (need <= *cap) return true;
    size_t c = *cap ? *cap : 16;
    while (c < need) {
        if (c > SIZE_MAX / 2 / elem) return false;
        c *= 2;
    }
    void *q = io_realloc(*p, c * elem);
    if (!q) return false;
    *p = q;
    *cap = c;
    return true;
}

uint32_t *io_scratch_u(io_ctx *ctx, size_t n) {
    if (!io_reserve((void **)&ctx->scratch_u, &ctx->scratch_u_cap, n, sizeof(uint32_t))) return NULL;
    return ctx->scratch_u;
}

float *io_scratch_f(io_ctx *ctx, size_t n) {
    if (!io_reserve((void **)&ctx->scratch_f, &ctx->scratch_f_cap, n, sizeof(float))) return NULL;
    return ctx->scratch_f;
}

float io_parse_float_slow(const char *start, const char *end, bool *ok) {
    /* Long mantissas and large exponents: rare, so the C library's correctly rounded strtof. The
     * text was already checked to be a plain decimal number ending at `end`. */
    char *e;
    float f = strtof(start, &e);
    *ok = e == end && isfinite(f); /* overflow gives HUGE_VALF; underflow to 0 or subnormal is fine */
    return f;
}

/* ---- builder ---------------------------------------------------------------------------------- */

void builder_material_defaults(rp_material_data *m, const char *name) {
    memset(m, 0, sizeof *m);
    snprintf(m->name, sizeof m->name, "%s", name);
    m->kd[0] = m->kd[1] = m->kd[2] = 0.8f;
    m->ior = 1.0f;
    m->illum = -1;
    m->map_kd = -1;
    m->alpha = 1.0f;
    m->alpha_cutoff = 0.5f;
}

uint32_t builder_add_material(io_ctx *ctx, const rp_material_data *m) {
    io_builder *b = &ctx->b;
    if (b->material_n >= UINT32_MAX - 1 ||
        !io_reserve((void **)&b->materials, &b->material_cap, b->material_n + 1, sizeof *m))
        return IO_NONE;
    b->materials[b->material_n] = *m;
    return (uint32_t)b->material_n++;
}

uint32_t builder_default_material(io_ctx *ctx) {
    if (ctx->b.default_material == IO_NONE) {
        rp_material_data m;
        builder_material_defaults(&m, "default");
        ctx->b.default_material = builder_add_material(ctx, &m);
    }
    return ctx->b.default_material;
}

/* What an array's first reservation asks for: the builder's hint when that is more. */
static size_t first_need(size_t cap, size_t need, size_t hint) { return cap == 0 && hint > need ? hint : need; }

bool builder_reserve_vertices(io_ctx *ctx, size_t extra) {
    io_builder *b = &ctx->b;
    return io_reserve((void **)&b->pos, &b->pos_cap, first_need(b->pos_cap, b->pos_n + extra, b->hint), 3 * sizeof(float));
}

bool builder_reserve_normals(io_ctx *ctx, size_t extra) {
    io_builder *b = &ctx->b;
    return io_reserve((void **)&b->nrm, &b->nrm_cap, first_need(b->nrm_cap, b->nrm_n + extra, b->hint), 3 * sizeof(float));
}

bool builder_reserve_texcoords(io_ctx *ctx, size_t extra) {
    io_builder *b = &ctx->b;
    return io_reserve((void **)&b->uv, &b->uv_cap, first_need(b->uv_cap, b->uv_n + extra, b->hint), 2 * sizeof(float));
}

bool builder_set_colors(io_ctx *ctx, size_t first, const float *rgb, size_t n) {
    io_builder *b = &ctx->b;
    size_t end = first + n;
    if (end > b->col_cap && !io_reserve((void **)&b->col, &b->col_cap, end > b->pos_cap ? end : b->pos_cap, 3 * sizeof(float)))
        return false;
    for (size_t i = b->col_n; i < first; i++) b->col[3 * i] = b->col[3 * i + 1] = b->col[3 * i + 2] = 1.0f;
    if (n) memcpy(b->col + 3 * first, rgb, 3 * sizeof(float) * n);
    if (end > b->col_n) b->col_n = end;
    return true;
}

float io_srgb_to_linear(float c) {
    if (!(c > 0.0f)) return 0.0f;
    if (c >= 1.0f) return 1.0f; /* a colour of 0-255 values in a file of [0, 1] ones: white, not 255x */
    return c <= 0.04045f ? c / 12.92f : powf((c + 0.055f) / 1.055f, 2.4f);
}

bool builder_reserve_triangles(io_ctx *ctx, size_t extra) {
    io_builder *b = &ctx->b;
    size_t need = first_need(b->tri_cap, b->tri_n + extra, b->hint / 2), cap = b->tri_cap;
    if (need <= cap) return true;
    /* The four per-triangle arrays grow together; nidx/tidx only once they exist. */
    size_t c = cap;
    if (!io_reserve((void **)&b->idx, &c, need, 3 * sizeof(uint32_t))) return false;
    c = cap;
    if (!io_reserve((void **)&b->mat, &c, need, sizeof(uint32_t))) return false;
    if (b->nidx) {
        c = cap;
        if (!io_reserve((void **)&b->nidx, &c, need, 3 * sizeof(uint32_t))) return false;
    }
    if (b->tidx) {
        c = cap;
        if (!io_reserve((void **)&b->tidx, &c, need, 3 * sizeof(uint32_t))) return false;
    }
    b->tri_cap = c;
    return true;
}

/* Allocates a per-corner index array for the triangles so far, every corner IO_NONE. */
static uint32_t *corner_array(const io_builder *b) {
    size_t cap = b->tri_cap ? b->tri_cap : 16;
    uint32_t *a = io_malloc(cap * 3 * sizeof(uint32_t));
    if (a) memset(a, 0xFF, b->tri_n * 3 * sizeof(uint32_t));
    return a;
}

bool builder_claim_triangles(io_ctx *ctx, size_t tris, bool normals, bool texcoords) {
    io_builder *b = &ctx->b;
    if (tris >= UINT32_MAX / 3 - b->tri_n || !builder_reserve_triangles(ctx, tris)) return false;
    if (normals && !b->nidx && !(b->nidx = corner_array(b))) return false;
    if (texcoords && !b->tidx && !(b->tidx = corner_array(b))) return false;
    b->tri_n += tris;
    return true;
}

bool builder_add_triangle(io_ctx *ctx, const uint32_t v[3], const uint32_t *n, const uint32_t *t,
                          uint32_t material) {
    io_builder *b = &ctx->b;
    if (b->tri_n >= b->tri_cap) {
        if (b->tri_n >= UINT32_MAX / 3 || !builder_reserve_triangles(ctx, 1)) return false;
        if (b->tri_cap < b->tri_n + 1) return false;
    }
    if (n && !b->nidx && !(b->nidx = corner_array(b))) return false;
    if (t && !b->tidx && !(b->tidx = corner_array(b))) return false;
    size_t i = b->tri_n++;
    memcpy(b->idx + 3 * i, v, 3 * sizeof(uint32_t));
    if (b->nidx) {
        if (n) memcpy(b->nidx + 3 * i, n, 3 * sizeof(uint32_t));
        else b->nidx[3 * i] = b->nidx[3 * i + 1] = b->nidx[3 * i + 2] = IO_NONE;
    }
    if (b->tidx) {
        if (t) memcpy(b->tidx + 3 * i, t, 3 * sizeof(uint32_t));
        else b->tidx[3 * i] = b->tidx[3 * i + 1] = b->tidx[3 * i + 2] = IO_NONE;
    }
    b->mat[i] = material;
    return true;
}

void builder_init(io_builder *b) {
    memset(b, 0, sizeof *b);
    b->default_material = IO_NONE;
}

void builder_free(io_builder *b) {
    free(b->pos);
    free(b->nrm);
    free(b->uv);
    free(b->col);
    free(b->idx);
    free(b->nidx);
    free(b->tidx);
    free(b->mat);
    free(b->spheres);
    free(b->cones);
    free(b->materials);
    for (size_t i = 0; i < b->texture_n; i++) {
        free(b->textures[i].rgb);
        free(b->textures[i].alpha);
        free(b->texture_keys[i]);
    }
    free(b->textures);
    free(b->texture_keys);
    free(b->texture_claimed);
    free(b->lights);
    memset(b, 0, sizeof *b);
}

/* Triangles that had no normal (an OBJ face without //n among faces with them, an NFF `p` among
 * `pp`) get their flat face normal, and those without texture coordinates the (0,0) coordinate, so
 * the per-corner arrays are either absent or complete. */
static bool builder_fill_missing(io_ctx *ctx) {
    io_builder *b = &ctx->b;
    if (b->col && b->col_n < b->pos_n && !builder_set_colors(ctx, b->pos_n, NULL, 0)) return false;
    if (b->col && b->col_n > b->pos_n) b->col_n = b->pos_n; /* a colour parsed with a vertex undone */
    if (b->nidx) {
        for (size_t i = 0; i < b->tri_n; i++) {
            uint32_t *n = b->nidx + 3 * i;
            if (n[0] != IO_NONE && n[1] != IO_NONE && n[2] != IO_NONE) continue;
            const float *p0 = b->pos + 3 * (size_t)b->idx[3 * i];
            const float *p1 = b->pos + 3 * (size_t)b->idx[3 * i + 1];
            const float *p2 = b->pos + 3 * (size_t)b->idx[3 * i + 2];
            float e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
            float e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
            float c[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                          e1[0] * e2[1] - e1[1] * e2[0]};
            float len = sqrtf(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
            if (len > 0.0f) {
                c[0] /= len, c[1] /= len, c[2] /= len;
            } else {
                c[0] = 0.0f, c[1] = 0.0f, c[2] = 1.0f; /* zero-area triangle: any unit vector */
            }
            if (b->nrm_n >= UINT32_MAX || !builder_reserve_normals(ctx, 1)) return false;
            memcpy(b->nrm + 3 * b->nrm_n, c, sizeof c);
            uint32_t k = (uint32_t)b->nrm_n++;
            for (int j = 0; j < 3; j++)
                if (n[j] == IO_NONE) n[j] = k;
        }
    }
    if (b->tidx) {
        uint32_t zero = IO_NONE;
        for (size_t i = 0; i < 3 * b->tri_n; i++) {
            if (b->tidx[i] != IO_NONE) continue;
            if (zero == IO_NONE) {
                if (b->uv_n >= UINT32_MAX || !builder_reserve_texcoords(ctx, 1)) return false;
                b->uv[2 * b->uv_n] = b->uv[2 * b->uv_n + 1] = 0.0f;
                zero = (uint32_t)b->uv_n++;
            }
            b->tidx[i] = zero;
        }
    }
    return true;
}

/* ---- entry points ----------------------------------------------------------------------------- */

static double now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static bool ends_with(const char *s, const char *suffix) {
    size_t n = strlen(s), k = strlen(suffix);
    return n >= k && strcmp(s + n - k, suffix) == 0;
}

static bool has_ext(const char *path, const char *ext) {
    char e[16];
    vfs_extension(path, e, sizeof e);
    return strcmp(e, ext) == 0;
}

static bool is_archive(const char *path) {
    char lower[IO_PATH_MAX];
    size_t n = strlen(path);
    if (n >= sizeof lower) return false;
    for (size_t i = 0; i <= n; i++) lower[i] = (char)(path[i] >= 'A' && path[i] <= 'Z' ? path[i] + 32 : path[i]);
    return ends_with(lower, ".tar") || ends_with(lower, ".tar.gz") || ends_with(lower, ".tgz");
}

/* The newline ending the line at p, or end. */
static const char *line_end(const char *p, const char *end) {
    const char *nl = p < end ? memchr(p, '\n', (size_t)(end - p)) : NULL;
    return nl ? nl : end;
}

/* Scans an AFF/NFF text for `i <detail> <file>` includes and marks the archive entries they name. */
static void mark_includes(io_ctx *ctx, const io_entry *e, bool *included) {
    const char *p = e->data, *end = e->data + e->size;
    while (p < end) {
        while (p < end && io_is_space(*p)) p++;
        if (p + 1 < end && p[0] == 'i' && io_is_space(p[1])) {
            p++;
            while (p < end && io_is_space(*p)) p++;
            while (p < end && !io_is_space(*p) && *p != '\n') p++; /* detail level */
            while (p < end && io_is_space(*p)) p++;
            const char *s = p;
            while (p < end && !io_is_space(*p) && *p != '\n' && *p != '\0') p++;
            char rel[IO_PATH_MAX], full[IO_PATH_MAX];
            size_t len = (size_t)(p - s);
            if (len > 0 && len < sizeof rel) {
                memcpy(rel, s, len);
                rel[len] = '\0';
                vfs_join(&ctx->vfs, e->name, rel, full, sizeof full);
                for (size_t k = 0; k < ctx->vfs.entry_count; k++)
                    if (strcmp(ctx->vfs.entries[k].name, full) == 0) included[k] = true;
            }
        }
        p = line_end(p, end) + 1;
    }
}

static size_t count_includes(const io_entry *e) {
    size_t n = 0;
    const char *p = e->data, *end = e->data + e->size;
    while (p < end) {
        while (p < end && io_is_space(*p)) p++;
        if (p + 1 < end && p[0] == 'i' && io_is_space(p[1])) n++;
        p = line_end(p, end) + 1;
    }
    return n;
}

/* The main scene of an archive: among its .aff/.nff files the ones no other file includes; of those
 * the one with the most includes (kitchen.aff, museum5.aff), ties to the first in archive order.
 * Archives without AFF/NFF files must hold exactly one .obj or .ply. */
static const char *archive_main(io_ctx *ctx) {
    io_vfs *v = &ctx->vfs;
    bool *included = io_calloc(v->entry_count + 1, sizeof(bool));
    if (!included) {
        io_error(ctx, v->archive, 0, "out of memory");
        return NULL;
    }
    for (size_t i = 0; i < v->entry_count; i++)
        if (has_ext(v->entries[i].name, "aff") || has_ext(v->entries[i].name, "nff"))
            mark_includes(ctx, &v->entries[i], included);
    const char *best = NULL;
    size_t best_inc = 0;
    for (size_t i = 0; i < v->entry_count; i++) {
        const io_entry *e = &v->entries[i];
        if (included[i] || !(has_ext(e->name, "aff") || has_ext(e->name, "nff"))) continue;
        size_t inc = count_includes(e);
        if (!best || inc > best_inc) best = e->name, best_inc = inc;
    }
    free(included);
    if (best) return best;
    const char *only = NULL;
    for (size_t i = 0; i < v->entry_count; i++) {
        const char *n = v->entries[i].name;
        if (has_ext(n, "obj") || has_ext(n, "ply")) {
            if (only) return NULL;
            only = n;
        }
    }
    return only;
}

static bool load_scene_file(io_ctx *ctx, const char *path, const char *shown) {
    char ext[16];
    vfs_extension(path, ext, sizeof ext);
    if (strcmp(ext, "obj") == 0) return obj_load(ctx, path);
    if (strcmp(ext, "ply") == 0) return ply_load(ctx, path);
    if (strcmp(ext, "nff") == 0 || strcmp(ext, "aff") == 0) return nff_load(ctx, path);
    if (strcmp(ext, "vdb") == 0) return vdb_load(ctx, path, shown);
    if (assimp_can_load(ext)) return assimp_load(ctx, path);
    /* a directory (a scene's folder: "../shared/scenes/cornell_box") or a name without a suffix is
     * told apart from an unknown suffix (whose '.' the message showed alone) */
    struct stat st;
    if (stat(path, &st) == 0 && S_ISDIR(st.st_mode))
        return io_error(ctx, shown, 0, "is a directory: give the scene file in it");
    if (!ext[0])
        return io_error(ctx, shown, 0, "no file name suffix to tell the scene's format by (expected .obj, .ply, .nff, .aff, .tar, .vdb, .gltf, .glb or another format assimp reads)");
    return io_error(ctx, shown, 0, "unknown scene format '.%s' (expected .obj, .ply, .nff, .aff, .tar, .vdb, .gltf, .glb or another format assimp reads)", ext);
}

static void move_out(io_builder *b, rp_scene_data *out) {
    out->vertex_count = b->pos_n;
    out->positions = b->pos;
    out->normal_count = b->nidx ? b->nrm_n : 0;
    out->normals = b->nidx ? b->nrm : NULL;
    if (!b->nidx) free(b->nrm);
    out->texcoord_count = b->tidx ? b->uv_n : 0;
    out->texcoords = b->tidx ? b->uv : NULL;
    if (!b->tidx) free(b->uv);
    out->triangle_count = b->tri_n;
    out->indices = b->idx;
    out->normal_indices = b->nidx;
    out->texcoord_indices = b->tidx;
    out->tri_materials = b->mat;
    out->colors = b->col; /* as many as positions: builder_fill_missing */
    out->sphere_count = b->sphere_n;
    out->spheres = b->spheres;
    out->cone_count = b->cone_n;
    out->cones = b->cones;
    out->material_count = b->material_n;
    out->materials = b->materials;
    out->texture_count = b->texture_n;
    out->textures = b->textures;
    for (size_t i = 0; i < b->texture_n; i++) free(b->texture_keys[i]);
    free(b->texture_keys);
    free(b->texture_claimed);
    out->light_count = b->light_n;
    out->lights = b->lights;
    out->camera = b->camera;
    memcpy(out->background, b->background, sizeof out->background);
    out->has_background = b->has_background;
    memset(b, 0, sizeof *b);
}

/* A limit from the environment (a positive integer, k/M/G suffixes allowed), else its default. */
static uint64_t env_limit(const char *name, uint64_t def) {
    const char *v = getenv(name);
    if (!v || !*v) return def;
    char *end;
    unsigned long long n = strtoull(v, &end, 10);
    uint64_t scale = *end == 'k' || *end == 'K' ? 1ull << 10 : *end == 'M' ? 1ull << 20 : *end == 'G' ? 1ull << 30 : 1;
    if (scale != 1) end++;
    if (end == v || *end != '\0' || n == 0 || n > UINT64_MAX / scale) return def;
    return (uint64_t)n * scale;
}

static void ctx_init(io_ctx *ctx, const io_load_opts *opts, char *err, size_t err_size) {
    memset(ctx, 0, sizeof *ctx);
    ctx->err = err;
    ctx->err_size = err_size;
    ctx->b.default_material = IO_NONE;
    ctx->threads = io_threads_resolve(opts ? opts->threads : 0);
    ctx->chunk_bytes = opts ? opts->chunk_bytes : 0;
    ctx->stream = opts ? opts->stream : 0;
    ctx->stream_block = opts ? opts->stream_block : 0;
    ctx->volume_grid = opts ? opts->volume_grid : NULL;
    ctx->warning = opts ? opts->warning : NULL;
    ctx->warning_user = opts ? opts->warning_user : NULL;
    ctx->limits.max_includes = env_limit("RP_MAX_INCLUDES", IO_DEFAULT_MAX_INCLUDES);
    ctx->limits.max_include_bytes = env_limit("RP_MAX_INCLUDE_BYTES", IO_DEFAULT_MAX_INCLUDE_BYTES);
    ctx->limits.max_file_bytes = env_limit("RP_MAX_FILE_BYTES", IO_DEFAULT_MAX_FILE_BYTES);
    ctx->limits.max_texture_pixels = env_limit("RP_MAX_TEXTURE_PIXELS", IO_DEFAULT_MAX_TEXTURE_PIXELS);
}

/* The archive's main scene, loaded (the archive already in ctx->vfs). */
static bool load_archive_main(io_ctx *ctx, const char *path) {
    const char *main_file = archive_main(ctx);
    if (!main_file)
        return io_error(ctx, path, 0, "archive holds no single main scene (.aff/.nff not included by another, or one .obj/.ply)");
    return load_scene_file(ctx, main_file, path);
}

/* After the loader: defaults, clean-up, and the builder's arrays handed to out. */
static bool ctx_finish(io_ctx *ctx, bool ok, const char *path, rp_scene_data *out, double t0, const io_load_opts *opts) {
    if (opts && opts->chunks_taken) *opts->chunks_taken = ctx->chunks_taken;
    if (opts && opts->blocks) *opts->blocks = ctx->blocks;
    if (ctx->warning && ctx->warnings > RP_LOAD_MAX_WARNINGS) {
        char msg[IO_PATH_MAX + 128];
        snprintf(msg, sizeof msg, "%s: warning: %u more warnings not shown", path,
                 ctx->warnings - RP_LOAD_MAX_WARNINGS);
        ctx->warning(ctx->warning_user, msg);
    }
    if (ok && ctx->b.material_n == 0) builder_default_material(ctx);
    if (ok && ctx->b.material_n == 0) ok = io_error(ctx, path, 0, "out of memory");
    if (ok && !builder_fill_missing(ctx)) ok = io_error(ctx, path, 0, "out of memory");
    free(ctx->scratch_u);
    free(ctx->scratch_f);
    vfs_close(&ctx->vfs);
    if (!ok) {
        if (!ctx->failed) io_error(ctx, path, 0, "load failed");
        builder_free(&ctx->b);
        anim_free(ctx->anim);
        ctx->anim = NULL;
        io_volume_free(ctx->volume);
        ctx->volume = NULL;
        return false;
    }
    move_out(&ctx->b, out);
    out->volume = ctx->volume;
    ctx->volume = NULL;
    if (!anim_finish(ctx, out)) {
        rp_scene_data_free(out);
        return io_error(ctx, path, 0, "out of memory");
    }
    if (!out->animation && out->vertex_count && !out->triangle_count && !out->sphere_count && !out->cone_count &&
        !io_points_to_spheres(out, opts ? opts->point_radius : 0.0f)) {
        rp_scene_data_free(out);
        return io_error(ctx, path, 0, "out of memory");
    }
    out->file_bytes = ctx->bytes;
    out->parse_ms = now_ms() - t0;
    return true;
}

/* Below this a text is parsed serially: threads cost more than they save on a few hundred kB. */
#define IO_MIN_CHUNK_BYTES (256u << 10)
#define IO_MAX_CHUNKS 65536u

uint32_t io_chunk_count(const io_ctx *ctx, size_t size) {
    if (ctx->chunk_bytes) { /* the tests' setting, even on one thread */
        size_t k = size / ctx->chunk_bytes + 1;
        return k > IO_MAX_CHUNKS ? IO_MAX_CHUNKS : (uint32_t)k;
    }
    if (ctx->threads <= 1 || size < 2 * (size_t)IO_MIN_CHUNK_BYTES) return 1;
    /* four chunks a thread, so a thread that was descheduled does not hold up the others */
    size_t k = (size_t)ctx->threads * 4, most = size / IO_MIN_CHUNK_BYTES;
    return (uint32_t)(k < most ? k : most);
}

void rp_scene_load_desc_defaults(rp_scene_load_desc *desc) {
    if (desc) memset(desc, 0, sizeof *desc);
}

bool io_load_file_opts(const char *path, const io_load_opts *opts, rp_scene_data *out, char *err, size_t err_size) {
    double t0 = now_ms();
    if (err && err_size) err[0] = '\0';
    if (!out) return false;
    memset(out, 0, sizeof *out);
    io_ctx ctx;
    ctx_init(&ctx, opts, err, err_size);
    if (!path) return io_error(&ctx, "(null)", 0, "no path given");
    if (strlen(path) >= IO_PATH_MAX - 64) return io_error(&ctx, path, 0, "path too long");
    bool ok;
    if (is_archive(path)) ok = vfs_open_archive(&ctx, path, NULL, 0) && load_archive_main(&ctx, path);
    else ok = load_scene_file(&ctx, path, path);
    return ctx_finish(&ctx, ok, path, out, t0, opts);
}

bool rp_scene_data_load_ex(const char *path, const rp_scene_load_desc *desc, rp_scene_data *out, char *err,
                           size_t err_size) {
    io_load_opts opts = {.threads = desc ? desc->threads : 0, .point_radius = desc ? desc->point_radius : 0.0f,
                         .volume_grid = desc ? desc->volume_grid : NULL,
                         .warning = desc ? desc->warning : NULL,
                         .warning_user = desc ? desc->warning_user : NULL};
    return io_load_file_opts(path, &opts, out, err, err_size);
}

bool rp_scene_data_load(const char *path, rp_scene_data *out, char *err, size_t err_size) {
    return io_load_file_opts(path, NULL, out, err, err_size);
}

bool io_load_memory(const io_entry *files, size_t n, bool archive, rp_scene_data *out, char *err, size_t err_size) {
    io_load_opts opts = {.threads = 1}; /* the fuzzers: one thread, as before */
    return io_load_memory_opts(files, n, archive, &opts, out, err, err_size);
}

bool io_load_memory_opts(const io_entry *files, size_t n, bool archive, const io_load_opts *opts, rp_scene_data *out,
                         char *err, size_t err_size) {
    double t0 = now_ms();
    if (err && err_size) err[0] = '\0';
    memset(out, 0, sizeof *out);
    io_ctx ctx;
    ctx_init(&ctx, opts, err, err_size);
    if (n == 0) return io_error(&ctx, "mem", 0, "no files");
    bool ok;
    if (archive) {
        ok = vfs_open_archive(&ctx, "mem", files[0].data, files[0].size) && load_archive_main(&ctx, "mem");
    } else {
        /* the caller's entries, borrowed: taken back out of the vfs before it is closed */
        ctx.vfs.archive = "mem";
        ctx.vfs.entries = (io_entry *)files;
        ctx.vfs.entry_count = n;
        ok = load_scene_file(&ctx, files[0].name, "mem");
        memset(&ctx.vfs, 0, sizeof ctx.vfs);
    }
    return ctx_finish(&ctx, ok, "mem", out, t0, opts);
}

void rp_scene_data_free(rp_scene_data *scene) {
    if (!scene) return;
    free(scene->positions);
    free(scene->normals);
    free(scene->texcoords);
    free(scene->indices);
    free(scene->normal_indices);
    free(scene->texcoord_indices);
    free(scene->colors);
    free(scene->sphere_colors);
    free(scene->tri_materials);
    free(scene->spheres);
    free(scene->cones);
    free(scene->materials);
    for (size_t i = 0; i < scene->texture_count; i++) {
        free(scene->textures[i].rgb);
        free(scene->textures[i].alpha);
    }
    free(scene->textures);
    free(scene->lights);
    anim_free(scene->animation);
    io_volume_free(scene->volume);
    memset(scene, 0, sizeof *scene);
}
