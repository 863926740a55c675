/* Internals shared by the scene loaders: the load context (files, errors), the scene builder the
 * parsers append to, the polygon triangulator and the number parsers.
 *
 * Every file a loader reads is held in memory, NUL-terminated one byte past its end, so parsers can
 * look one character ahead without bounds checks: the NUL stops every digit and word loop. */
#ifndef RP_IO_INTERNAL_H
#define RP_IO_INTERNAL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "raypack_io.h"

#define IO_PATH_MAX 1024
#define IO_NONE UINT32_MAX /* "no normal / texcoord for this corner" while building */

/* ---- files ------------------------------------------------------------------------------------ */

/* A whole file in memory; data[size] == '\0'. */
typedef struct io_buf {
    char *data;
    size_t size;
    bool owned; /* false: borrowed from the archive */
} io_buf;

typedef struct io_entry {
    char *name; /* normalized path inside the archive */
    char *data; /* NUL-terminated */
    size_t size;
} io_entry;

/* Where relative paths resolve: the disk, or the entries of one tar archive. */
typedef struct io_vfs {
    const char *archive; /* path of the archive, NULL: the disk */
    io_entry *entries;
    size_t entry_count;
    char *image; /* the inflated .tar.gz the entries point into, when they do; freed with them */
    size_t image_size;
} io_vfs;

/* ---- allocation (io_alloc.c) ----------------------------------------------------------------- */

/* Every allocation of the loaders goes through these: malloc, calloc, realloc and strdup, asking
 * the hook first; what they return is freed with free(). A hook returning false refuses that
 * allocation (the call returns NULL), which is how tests fail the k-th one; NULL (the default)
 * refuses none. Process-wide: install it while no load runs. */
typedef bool (*io_alloc_hook_fn)(void *user, size_t size);
void io_set_alloc_hook(io_alloc_hook_fn fn, void *user);
/* Asks the hook about an allocation made elsewhere (a library call that allocates: a zlib or
 * libarchive handle), so that failure path is tested too; true when it may go ahead. */
bool io_alloc_ok(size_t size);
/* How many allocations of the calling thread have failed so far (refused or out of memory): a
 * library that says "corrupt image" when its malloc failed is told apart by comparing two counts. */
unsigned long io_alloc_failures(void);
void *io_malloc(size_t size);
void *io_calloc(size_t n, size_t size);
void *io_realloc(void *p, size_t size);
char *io_strdup(const char *s);

/* ---- builder ---------------------------------------------------------------------------------- */

typedef struct io_builder {
    float *pos;
    size_t pos_n, pos_cap; /* in vertices */
    float *nrm;
    size_t nrm_n, nrm_cap;
    float *uv;
    size_t uv_n, uv_cap;
    float *col;            /* colours of vertices [0, col_n) (linear RGB), or NULL: none yet */
    size_t col_n, col_cap;
    uint32_t *idx, *nidx, *tidx, *mat; /* nidx/tidx allocated lazily, IO_NONE where absent */
    size_t tri_n, tri_cap;
    rp_sphere_data *spheres;
    size_t sphere_n, sphere_cap;
    rp_cone_data *cones;
    size_t cone_n, cone_cap;
    rp_material_data *materials;
    size_t material_n, material_cap;
    rp_texture_data *textures;
    size_t texture_n, texture_cap;
    char **texture_keys; /* resolved path of each texture, for sharing */
    bool *texture_claimed; /* tex_sampled has given the entry's sampler to a use (see there) */
    rp_light_data *lights;
    size_t light_n, light_cap;
    rp_camera_data camera;
    float background[3];
    bool has_background;
    uint32_t default_material; /* IO_NONE until needed */
    size_t hint; /* vertices the first reservation of pos, nrm and uv makes room for (triangles: half
                  * as many); a parallel chunk's estimate from its lines, so it grows without copies */
} io_builder;

/* ---- load context ----------------------------------------------------------------------------- */

/* What a scene may cost before it is refused (hostile files: include bombs, gzip bombs). The
 * defaults fit every shared scene many times over; environment variables raise them
 * (RP_MAX_INCLUDES, RP_MAX_INCLUDE_BYTES, RP_MAX_FILE_BYTES, RP_MAX_TEXTURE_PIXELS; see README). */
typedef struct io_limits {
    uint64_t max_includes;      /* AFF/NFF `i` files parsed, all levels together */
    uint64_t max_include_bytes; /* bytes of those files, after decompression */
    uint64_t max_file_bytes;    /* one file after decompression */
    uint64_t max_texture_pixels; /* one decoded PNG/JPEG texture (a 100-byte PNG may claim 10^9) */
} io_limits;
#define IO_DEFAULT_MAX_INCLUDES 4096u
#define IO_DEFAULT_MAX_INCLUDE_BYTES (1ull << 30)
#define IO_DEFAULT_MAX_FILE_BYTES (4ull << 30)
#define IO_DEFAULT_MAX_TEXTURE_PIXELS (1ull << 26)

typedef struct io_ctx {
    io_vfs vfs;
    io_builder b;
    char *err;
    size_t err_size;
    bool failed;
    size_t bytes;  /* scene text parsed, after decompression */
    int depth;     /* include nesting */
    io_limits limits;
    uint64_t includes, include_bytes; /* spent so far, against the limits */
    char why[256]; /* why the last vfs_read failed */
    uint32_t *scratch_u; /* per-polygon scratch, grown as needed */
    size_t scratch_u_cap;
    float *scratch_f;
    size_t scratch_f_cap;
    int threads;        /* resolved: threads that parse a large file's chunks (1: serial) */
    size_t chunk_bytes; /* chunk size for the parallel parsers; 0: chosen from the file and threads */
    size_t chunks_taken; /* chunks whose parallel result was used (for the tests) */
    int stream;          /* gzip'd NFF and OBJ read in blocks (io_stream): 0 when large and threads > 1, 1 always, -1 never */
    size_t stream_block; /* text per block; 0: IO_STREAM_BLOCK */
    size_t blocks;       /* blocks a streamed load parsed (for the tests) */
    rp_animation_data *anim; /* what the AFF loader parsed of an animation, finished by anim_finish */
    rp_volume_data *volume;  /* what vdb_load read, handed to rp_scene_data.volume */
    const char *volume_grid; /* rp_scene_load_desc.volume_grid */
    void (*warning)(void *user, const char *message); /* rp_scene_load_desc.warning */
    void *warning_user;
    uint32_t warnings; /* written so far (io_warning) */
} io_ctx;

/* Records the first error as "file:line: error: message"; always returns false. */
bool io_error(io_ctx *ctx, const char *file, uint32_t line, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* Passes "file:line: warning: message" to the load's warning callback, if any (the load goes on);
 * past RP_LOAD_MAX_WARNINGS, only counted (their number is passed on when the load ends). */
void io_warning(io_ctx *ctx, const char *file, uint32_t line, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* Grows *p to hold at least `need` elements of `elem` bytes, geometrically; false when out of memory. */
bool io_reserve(void **p, size_t *cap, size_t need, size_t elem);
/* Scratch arrays for one polygon (n indices, 3n floats); NULL when out of memory. */
uint32_t *io_scratch_u(io_ctx *ctx, size_t n);
float *io_scratch_f(io_ctx *ctx, size_t n);

/* ---- files (io_vfs.c) ------------------------------------------------------------------------- */

/* Reads `path` (on disk: gzip'd or plain, a regular file or a stream; in an archive: an entry).
 * Writes no error; on failure ctx->why says why (errno's text, "corrupt gzip data", ...). */
bool vfs_read(io_ctx *ctx, const char *path, io_buf *out);
/* True when `path` can be read. */
bool vfs_exists(io_ctx *ctx, const char *path);
void vfs_buf_free(io_buf *buf);
/* Reads every regular file of a tar (.tar, .tar.gz) archive into ctx->vfs: the file at path, or the
 * archive's bytes in memory when data is not NULL (path then only names it in errors). */
bool vfs_open_archive(io_ctx *ctx, const char *path, const void *data, size_t size);
void vfs_close(io_vfs *vfs);
/* dir of `base` + `rel` into out (lexically normalized inside archives). */
void vfs_join(const io_vfs *vfs, const char *base, const char *rel, char *out, size_t size);
/* The name errors use for `path`: "archive/entry" inside an archive. */
void vfs_display(const io_vfs *vfs, const char *path, char *out, size_t size);
/* Archive entry whose base name is `name`, when exactly one is; NULL otherwise. */
const char *vfs_find_basename(const io_vfs *vfs, const char *name);
/* Lower-case extension of path after stripping ".gz" ("obj", "tar", ...); "" if none. */
void vfs_extension(const char *path, char *ext, size_t size);

/* ---- streamed gzip text (io_stream.c) --------------------------------------------------------- */

/* A gzip'd text file inflated block by block on a thread of its own while the caller parses the
 * block before (io_stream.c); the text is never held whole. */
typedef struct io_stream io_stream;
/* One block: complete lines (a last block may end without a newline), data[size] == '\0'. Valid
 * until io_stream_release gives it back; blocks are given back in the order they came. */
typedef struct io_text {
    const char *data;
    size_t size;
    bool last; /* the file ends with this block */
} io_text;
/* Where a block of size bytes ends: a line start in (0, size], the rest carried to the next block;
 * 0 when there is none (the block then grows). */
typedef size_t (*io_cut_fn)(const char *data, size_t size);
/* The default cut: after the last newline. */
size_t io_cut_lines(const char *data, size_t size);
#define IO_STREAM_BLOCK ((size_t)8 << 20)     /* most text inflated per block (4 blocks at once at most) */
#define IO_STREAM_MIN_BLOCK ((size_t)1 << 20) /* least: blocks are an eighth of the file between the two */
/* Gzip files of less text than this (as their trailer states) are read whole: libdeflate inflates
 * 3-4x faster than zlib's stream, and below some tens of MB that saves more than the page faults
 * on the whole text cost (the Conference room's 12 MB loaded slower streamed, the rings' 36 MB
 * faster; docs/loading.md). */
#define IO_STREAM_MIN_TEXT ((size_t)24 << 20)
/* Starts streaming path when it is a regular gzip file on disk whose trailer states at least
 * min_text bytes of text (0: any gzip file); NULL otherwise (or when out of memory): the caller
 * then reads it whole, with vfs_read's errors.
 * block: text inflated per block (0: chosen from the size; the tests cut every line with a few bytes);
 * cut: NULL for io_cut_lines. ctx->limits.max_file_bytes caps the inflated size. */
io_stream *io_stream_open(io_ctx *ctx, const char *path, size_t min_text, size_t block, io_cut_fn cut);
/* The next block, waiting for it; false when the file is bad (ctx->why says why, in vfs_read's
 * words: "corrupt or truncated gzip data (...)", the size limit, ...). */
bool io_stream_next(io_stream *s, io_ctx *ctx, io_text *out);
void io_stream_release(io_stream *s);
/* Reads the rest of the file (after a parse error: whether the file itself was good, which a
 * whole-buffer read would have said first); false with ctx->why when it was not. */
bool io_stream_drain(io_stream *s, io_ctx *ctx);
/* Bytes inflated so far (all of them once the last block was handed out). */
uint64_t io_stream_total(const io_stream *s);
/* The inflated size the file's gzip trailer states (a multi-member file's last member only), for
 * presizing; 0 when it is not plausible. */
uint64_t io_stream_size_hint(const io_stream *s);
void io_stream_close(io_stream *s);

/* ---- builder (io_scene.c) --------------------------------------------------------------------- */

uint32_t builder_default_material(io_ctx *ctx);
/* Appends a material (kd etc. filled by the caller); returns its index or IO_NONE (out of memory). */
uint32_t builder_add_material(io_ctx *ctx, const rp_material_data *m);
bool builder_add_triangle(io_ctx *ctx, const uint32_t v[3], const uint32_t *n, const uint32_t *t,
                          uint32_t material);
/* Counts `tris` more triangles whose arrays (idx, mat, and nidx/tidx where they exist) the caller
 * writes itself later, before anything reads them; with `normals` (`texcoords`), nidx (tidx) exists
 * afterwards, the triangles before them IO_NONE. For the parallel parsers' chunks. */
bool builder_claim_triangles(io_ctx *ctx, size_t tris, bool normals, bool texcoords);
bool builder_reserve_vertices(io_ctx *ctx, size_t extra);
/* Frees every array of a builder (a chunk's, or the scene's after a failure) and zeroes it. */
void builder_free(io_builder *b);
/* A builder for one chunk of a parallel parse (default material IO_NONE, nothing allocated). */
void builder_init(io_builder *b);
bool builder_reserve_normals(io_ctx *ctx, size_t extra);
bool builder_reserve_texcoords(io_ctx *ctx, size_t extra);
/* Colours vertices [first, first + n) (linear RGB, 3 n floats); vertices before first without one
 * are white. */
bool builder_set_colors(io_ctx *ctx, size_t first, const float *rgb, size_t n);
/* The sRGB transfer function's inverse, for 8-bit (or normalized) colours written in files; clamped
 * to [0, 1] (NaN to 0). */
float io_srgb_to_linear(float c);
bool builder_reserve_triangles(io_ctx *ctx, size_t extra);
/* Material initialised to the defaults of every format (grey diffuse, ior 1, no texture). */
void builder_material_defaults(rp_material_data *m, const char *name);

/* ---- textures (io_texture.c) ------------------------------------------------------------------ */

/* Loads (or finds already loaded) the texture at resolved path `path`, named `as_written` in the
 * scene; returns its index, or IO_NONE after writing an error at file:line. */
uint32_t tex_load(io_ctx *ctx, const char *path, const char *as_written, const char *file,
                  uint32_t line);
/* Adds a texture decoded from an encoded image in memory (PNG, JPEG, ...; embedded in a scene
 * file), shared under `key`; returns its index or IO_NONE after an error at file:line. */
uint32_t tex_add_encoded(io_ctx *ctx, const char *key, const char *as_written, const void *data,
                         size_t size, const char *file, uint32_t line);
/* Adds decoded 8-bit RGB texels and their alpha plane (NULL: opaque) (malloc'ed; taken over, freed
 * on failure) under `key`. */
uint32_t tex_add(io_ctx *ctx, const char *key, const char *as_written, int32_t width, int32_t height,
                 uint8_t *rgb, uint8_t *alpha, const char *file, uint32_t line);
/* How a scene reads a texture: rp_texture_data's wrap modes and filter, and MTL -mm's remap of
 * every stored value v (colour channels as stored, sRGB-encoded, and the alpha plane) to
 * mm_base + mm_gain v, clamped to [0, 1]. {0, 0, 0, 0, 1} (repeat, bilinear, identity) is the
 * default. */
typedef struct tex_sampler {
    rp_texture_wrap wrap_u, wrap_v;
    rp_texture_filter filter;
    float mm_base, mm_gain;
} tex_sampler;
#define TEX_SAMPLER_DEFAULT ((tex_sampler){RP_TEXTURE_REPEAT, RP_TEXTURE_REPEAT, RP_TEXTURE_LINEAR, 0.0f, 1.0f})
/* Texture `image` read under sampler *s: `image` itself when *s is what it already has (and no
 * remap), else an entry of its own (a copy of the texels, remapped), shared per (image, sampler);
 * IO_NONE after an error (out of memory) at file:line. */
uint32_t tex_sampled(io_ctx *ctx, uint32_t image, const tex_sampler *s, const char *file, uint32_t line);
/* Bump maps (MTL bump, map_bump): a grey height map h in [0, 1] (the mean of the channels)
 * becomes a tangent-space normal map at load time, normal (-s dh/du, -s dh/dv, 1) normalised, the
 * derivatives central differences in texels and s = scale (MTL -bm) x IO_BUMP_STRENGTH: with -bm 1
 * the steepest step an 8-bit map holds, black to white between neighbouring texels (a central
 * difference of 0.5), tilts the normal 45 degrees. Shared per (image, scale). */
#define IO_BUMP_STRENGTH 2.0f
enum { TEX_BUMP_HEIGHT, TEX_BUMP_FLAT, TEX_BUMP_NORMALS };
/* What a bump map's image holds: heights, one height everywhere (no relief), or (bluish and far
 * from grey) a tangent-space normal map, as Blender's exporter writes under map_Bump. */
int tex_bump_kind(io_ctx *ctx, uint32_t height);
/* The normal map of height map `height` (a texture index); IO_NONE after an error at file:line. */
uint32_t tex_bump_to_normal(io_ctx *ctx, uint32_t height, float scale, const char *file, uint32_t line);

/* ---- loading from memory (io_scene.c; for the fuzzers and tests) ------------------------------- */

/* Loads the scene files[0] (its name gives the format) with files[1..n) serving its includes,
 * material libraries and textures, as if they were the entries of an archive named "mem"; with
 * archive, files[0] holds a tar(.gz) image instead and is unpacked first. The files stay the
 * caller's. Same result and errors as rp_scene_data_load. */
bool io_load_memory(const io_entry *files, size_t n, bool archive, rp_scene_data *out, char *err, size_t err_size);

/* Loading options for the tests: threads (0: all hardware threads) and the chunk size of the
 * parallel parsers (0: chosen per file; a few bytes puts chunk boundaries everywhere, which is
 * how the tests check that chunked parsing gives the serial result). */
typedef struct io_load_opts {
    int threads;
    size_t chunk_bytes;
    size_t *chunks_taken; /* when not NULL: set to the number of chunks whose parallel result was used */
    float point_radius;   /* rp_scene_load_desc.point_radius */
    int stream;           /* io_ctx.stream: 0 chosen per file, 1 stream every gzip'd NFF and OBJ on disk, -1 never */
    size_t stream_block;  /* io_ctx.stream_block (the tests: a few bytes, so blocks cut every line) */
    size_t *blocks;       /* when not NULL: set to the number of blocks a streamed load parsed */
    const char *volume_grid; /* rp_scene_load_desc.volume_grid */
    void (*warning)(void *user, const char *message); /* rp_scene_load_desc.warning */
    void *warning_user;
} io_load_opts;
/* A scene of vertices alone (a point cloud) gets a sphere of that radius (0: automatic) at each
 * finite vertex (io_points.c); false when out of memory. */
bool io_points_to_spheres(rp_scene_data *s, float radius);
/* io_load_memory and rp_scene_data_load with those options. */
bool io_load_memory_opts(const io_entry *files, size_t n, bool archive, const io_load_opts *opts, rp_scene_data *out,
                         char *err, size_t err_size);
bool io_load_file_opts(const char *path, const io_load_opts *opts, rp_scene_data *out, char *err, size_t err_size);

/* ---- threads (io_par.c) ----------------------------------------------------------------------- */

typedef void (*io_task_fn)(void *user, uint32_t index);
/* threads <= 0: the hardware threads; capped at 64. */
int io_threads_resolve(int threads);
/* Runs fn(user, i) for i in [0, count) on up to `threads` threads, the caller's among them. */
void io_parallel_for(int threads, uint32_t count, io_task_fn fn, void *user);
/* Chunks a text of `size` bytes is parsed in (1: serially), from ctx->threads and chunk_bytes. */
uint32_t io_chunk_count(const io_ctx *ctx, size_t size);
/* The vertices a chunk of text [p, end) probably holds, for io_builder.hint: one a line (SPD, OBJ
 * and PLY write one a line), and no more than one per 6 bytes ("0 0 0\n"). */
size_t io_text_vertex_hint(const char *p, const char *end);
/* Cuts a text of `size` bytes into at most k pieces that start at line starts (the first at data),
 * writing their starts in order to starts[0, k); returns how many there are (0 for an empty text). */
uint32_t io_split_lines(const char *data, size_t size, uint32_t k, const char **starts);
/* ---- animation (io_anim.c) ------------------------------------------------------------------ */

/* Completes ctx->anim against the finished scene (per-vertex and per-normal nodes, rest copies)
 * and hands it to out at the animation's start time; false when out of memory. */
bool anim_finish(io_ctx *ctx, rp_scene_data *out);
/* Frees an animation and every array it owns. */
void anim_free(rp_animation_data *a);
/* Inverse of an affine row-major 3x4 matrix (m and out may not alias); false when singular or not
 * finite. rp_scene_data_set_time moves a block by rest * keys * rest^-1, so the AFF loader refuses
 * a block whose rest transform this cannot invert. */
bool anim_inverse(const double *m, double *out);

/* ---- polygons (io_poly.c) --------------------------------------------------------------------- */

/* Triangulates the simple polygon of n points (xyz each): a fan when it is convex, ear clipping
 * otherwise. Writes 3(n-2) indices into [0, n) to tris; scratch holds n uint32. */
void poly_triangulate(const float *pts, uint32_t n, uint32_t *tris, uint32_t *scratch);

/* ---- loaders ---------------------------------------------------------------------------------- */

bool obj_load(io_ctx *ctx, const char *path);
bool ply_load(io_ctx *ctx, const char *path);
bool nff_load(io_ctx *ctx, const char *path);
/* glTF and the other formats of assimp (io_assimp.c); assimp_can_load takes an extension ("glb"). */
bool assimp_load(io_ctx *ctx, const char *path);
/* An OpenVDB file's density grid into ctx->volume (io_volume.c); errors name `shown`. */
bool vdb_load(io_ctx *ctx, const char *path, const char *shown);
bool assimp_can_load(const char *ext);

/* ---- numbers ---------------------------------------------------------------------------------- */

static inline bool io_is_digit(char c) { return (unsigned)(c - '0') < 10u; }
/* Past a UTF-8 byte order mark at a text file's start (Windows tools write one); p when none. */
static inline const char *io_skip_bom(const char *p, const char *end) {
    return end - p >= 3 && (unsigned char)p[0] == 0xEF && (unsigned char)p[1] == 0xBB && (unsigned char)p[2] == 0xBF ? p + 3 : p;
}
static inline bool io_is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

/* Exact powers of ten for the fast path (Clinger 1990): 10^k is exact in a double for k <= 22. */
static const double io_pow10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                    1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                    1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

float io_parse_float_slow(const char *start, const char *end, bool *ok);

/* Parses a decimal float at p (sign, digits, point, exponent); returns the end, or NULL when there
 * is no number or it is out of float range. Correctly rounded: the fast path is a single exact
 * double operation whose result is rounded to float only when that rounding is not a tie;
 * everything else goes to strtof. NaN/Inf spellings are not numbers here. */
static inline const char *io_parse_float(const char *p, float *out) {
    const char *start = p;
    bool neg = false;
    if (*p == '-') {
        neg = true;
        p++;
    } else if (*p == '+') {
        p++;
    }
    uint64_t m = 0;
    int digits = 0, exp10 = 0;
    bool any = false, truncated = false;
    while (io_is_digit(*p)) {
        if (digits < 19) {
            m = m * 10 + (uint64_t)(*p - '0');
            if (m) digits++;
        } else {
            exp10++;
            truncated |= *p != '0';
        }
        p++;
        any = true;
    }
    if (*p == '.') {
        p++;
        while (io_is_digit(*p)) {
            if (digits < 19) {
                m = m * 10 + (uint64_t)(*p - '0');
                if (m) digits++;
                exp10--;
            } else {
                truncated |= *p != '0';
            }
            p++;
            any = true;
        }
    }
    if (!any) return NULL;
    if (*p == 'e' || *p == 'E') {
        const char *q = p + 1;
        bool eneg = false;
        if (*q == '-') {
            eneg = true;
            q++;
        } else if (*q == '+') {
            q++;
        }
        if (io_is_digit(*q)) {
            int e = 0;
            while (io_is_digit(*q)) {
                if (e < 100000) e = e * 10 + (*q - '0');
                q++;
            }
            exp10 += eneg ? -e : e;
            p = q;
        }
    }
    if (m == 0) {
        *out = neg ? -0.0f : 0.0f;
        return p;
    }
    if (!truncated && m < (1ull << 53) && exp10 >= -22 && exp10 <= 22) {
        double d = (double)m;
        d = exp10 < 0 ? d / io_pow10[-exp10] : d * io_pow10[exp10];
        uint64_t bits;
        memcpy(&bits, &d, sizeof bits);
        if ((bits & 0x1FFFFFFFu) != 0x10000000u) { /* not a float tie: rounding once more is exact */
            float f = (float)d;
            *out = neg ? -f : f;
            return p;
        }
    }
    bool ok;
    *out = io_parse_float_slow(start, p, &ok);
    return ok ? p : NULL;
}

/* Parses an optionally signed decimal integer; NULL when there is none or it overflows int64. */
static inline const char *io_parse_int(const char *p, int64_t *out) {
    bool neg = false;
    if (*p == '-') {
        neg = true;
        p++;
    } else if (*p == '+') {
        p++;
    }
    if (!io_is_digit(*p)) return NULL;
    uint64_t v = 0;
    int n = 0;
    while (io_is_digit(*p)) {
        v = v * 10 + (uint64_t)(*p - '0');
        if (++n > 18) return NULL;
        p++;
    }
    *out = neg ? -(int64_t)v : (int64_t)v;
    return p;
}

/* Writes an OpenEXR image of float channels (image_exr.c); channels 1 or 3. */
bool io_image_write_exr(const char *path, int width, int height, int channels, const float *pixels, char *err,
                        size_t err_size);
/* Writes a Radiance HDR image (image_hdr.c); channels 1 or 3. */
bool io_image_write_hdr(const char *path, int width, int height, int channels, const float *pixels, char *err,
                        size_t err_size);

#endif
