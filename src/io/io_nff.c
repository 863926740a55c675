/* NFF (Eric Haines' Standard Procedural Databases) and its superset AFF (BART, Lext, Assarsson and
 * Moller 2001): a stream of whitespace-separated commands, parsed in one pass over the file in
 * memory. Includes recurse into the same parser; transform blocks are a stack of 3x4 matrices
 * applied as primitives are emitted. Keyframed transforms (`x name {...}`) get their keyframes
 * from a `k name` block that may come later, so their geometry is stored as if the keyframed
 * transforms were the identity ("rest" space) and recorded as index ranges; the animation
 * (nodes, keys, `tpa` keys, `a` range) goes to ctx->anim, and io_anim.c moves the scene to the
 * animation's start once the whole scene is read. */
#include <math.h>
#include <stdio.h>

#include "io/io_internal.h"

#define NFF_MAX_DEPTH 64
#define NFF_MAX_INCLUDE 32

typedef struct nff_xf {
    float m[12];  /* rows of a 3x4 affine matrix */
    float nm[9];  /* normal matrix: inverse transpose of the 3x3 part (up to scale) */
    float scale;  /* radius scale for spheres and cones */
    bool identity;
} nff_xf;

/* An `x name {` block: what it holds, and the transform above it when it was opened. */
typedef struct nff_anim_node {
    char name[64];
    nff_xf parent;
    int parent_node; /* enclosing `x` block, -1 */
    size_t tri0, tri1, sph0, sph1, cone0, cone1, light0, light1;
} nff_anim_node;

/* A `k name {` block: its tracks in the key arrays. */
typedef struct nff_keys {
    char name[64];
    rp_anim_track track[3];
    uint32_t vis_first, vis_count;
} nff_keys;

typedef struct nff_level {
    nff_xf xf;
    int anim; /* index of the anim node, -1 for `xs` */
    uint32_t line;
    const char *file;
} nff_level;

typedef struct nff_state {
    uint32_t material; /* IO_NONE: the default material */
    int detail;
    nff_level stack[NFF_MAX_DEPTH + 1];
    int depth;
    nff_anim_node *anims;
    size_t anim_n, anim_cap;
    nff_keys *keys;
    size_t key_n, key_cap;
    uint32_t (*tex_mats)[3]; /* (base material, texture) -> material */
    size_t tex_mat_n, tex_mat_cap;
    size_t f_count;
    rp_anim_key *akeys; /* every `k` block's spline keys */
    size_t akey_n, akey_cap;
    float *vis_t;
    uint8_t *vis_v;
    size_t vis_n, vis_cap, vis_cap2;
    rp_anim_tpa *tpas;
    size_t tpa_n, tpa_cap;
    float *tpa_keys; /* 19 floats per key */
    size_t tpak_n, tpak_cap;
    bool has_range;
    float start, end;
    int32_t frames;
    float ambient[3]; /* `am`: the global ambient light (0 when the file gives none) */
} nff_state;

typedef struct nff_file {
    io_ctx *ctx;
    nff_state *st;
    const char *path;
    char shown[IO_PATH_MAX + 256];
    const char *p, *end;
    uint32_t line;
    /* A streamed file (io_stream) is parsed a window at a time: `more` says the file goes on after
     * end. A command that needs text past end sets `starved` and fails without an error message;
     * the stream loop undoes what it did (nff_mark) and parses it again on a larger window. */
    bool more, starved;
    nff_keys saved_key;    /* a `k` block's earlier keys of the same name, overwritten by a starved one */
    size_t saved_key_at;   /* index of saved_key in st->keys; SIZE_MAX: none */
} nff_file;

/* ---- tokens ----------------------------------------------------------------------------------- */

static inline void nff_skip(nff_file *f) {
    const char *p = f->p;
    for (;;) {
        char c = *p;
        if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
            p++;
        } else if (c == '\n') {
            f->line++;
            p++;
        } else if (c == '#' || c == '%') { /* comment to the end of the line, also after data */
            while (*p != '\n' && p < f->end) p++;
        } else {
            break;
        }
    }
    f->p = p;
}

static inline bool nff_delim(char c) {
    return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\0' || c == '#' || c == '%' || c == '\f' ||
           c == '\v';
}

/* A short printable copy of the token at p, for messages. */
static const char *nff_preview(const nff_file *f, const char *p, char *buf, size_t size) {
    size_t n = 0;
    while (n + 1 < size && p + n < f->end && !nff_delim(p[n])) {
        unsigned char c = (unsigned char)p[n];
        buf[n] = c >= 32 && c < 127 ? (char)c : '?';
        n++;
    }
    buf[n] = '\0';
    return buf;
}

/* At the end of the text: an error, or in a window that the file goes on after, starvation. */
static bool nff_eof_error(nff_file *f, const char *what) {
    if (f->more) {
        f->starved = true;
        return false;
    }
    return io_error(f->ctx, f->shown, f->line, "unexpected end of file, expected %s (truncated file?)", what);
}

static inline bool nff_float(nff_file *f, float *v, const char *what) {
    nff_skip(f);
    const char *q = io_parse_float(f->p, v);
    if (q && nff_delim(*q)) {
        f->p = q;
        return true;
    }
    if (f->p >= f->end) return nff_eof_error(f, what);
    char tok[32];
    return io_error(f->ctx, f->shown, f->line, "%s: expected a finite number, got '%s'", what,
                    nff_preview(f, f->p, tok, sizeof tok));
}

static bool nff_floats(nff_file *f, float *v, int n, const char *what) {
    for (int i = 0; i < n; i++)
        if (!nff_float(f, &v[i], what)) return false;
    return true;
}

/* v[first..first+n-1] are colours or reflection coefficients: a negative one rendered negative
 * radiance (Whitted's image had pixels below 0). */
static bool nff_nonnegative(nff_file *f, const float *v, int first, int n, const char *what) {
    for (int i = first; i < first + n; i++)
        if (v[i] < 0.0f)
            return io_error(f->ctx, f->shown, f->line, "%s: negative colour or coefficient %g (expected >= 0)", what,
                            (double)v[i]);
    return true;
}

static bool nff_int(nff_file *f, int64_t *v, const char *what) {
    nff_skip(f);
    const char *q = io_parse_int(f->p, v);
    if (q && nff_delim(*q)) {
        f->p = q;
        return true;
    }
    if (f->p >= f->end) return nff_eof_error(f, what);
    char tok[32];
    return io_error(f->ctx, f->shown, f->line, "%s: expected an integer, got '%s'", what,
                    nff_preview(f, f->p, tok, sizeof tok));
}

/* Next word (up to a delimiter) into out; false at end of file or when too long. */
static bool nff_word(nff_file *f, char *out, size_t size, const char *what) {
    nff_skip(f);
    if (f->p >= f->end) return nff_eof_error(f, what);
    size_t n = 0;
    while (!nff_delim(f->p[n])) n++;
    if (n == 0 || n >= size) {
        char tok[32];
        return io_error(f->ctx, f->shown, f->line, "%s: bad or too long word '%s'", what,
                        nff_preview(f, f->p, tok, sizeof tok));
    }
    memcpy(out, f->p, n);
    out[n] = '\0';
    f->p += n;
    return true;
}

/* True when the next token starts like a number (optional light colours). */
static bool nff_number_next(nff_file *f) {
    nff_skip(f);
    if (f->p >= f->end && f->more) f->starved = true;
    char c = *f->p;
    return io_is_digit(c) || ((c == '-' || c == '+' || c == '.') && (io_is_digit(f->p[1]) || f->p[1] == '.'));
}

static bool nff_expect(nff_file *f, char c, const char *after) {
    nff_skip(f);
    if (*f->p == c && f->p < f->end) {
        f->p++;
        return true;
    }
    if (f->p >= f->end && f->more) return nff_eof_error(f, "'{'"); /* starved: a window ends here */
    return io_error(f->ctx, f->shown, f->line, "expected '%c' after %s", c, after);
}

/* Whether n items of at least `per` bytes of text each can follow: counts a file cannot hold are
 * refused before anything is allocated for them. In a window the file goes on after, a count too
 * large for the window starves the command instead (it is parsed again on a larger window). */
static bool nff_fits(nff_file *f, int64_t n, size_t per) {
    if ((uint64_t)n <= (uint64_t)(f->end - f->p) / per + 1) return true;
    if (f->more) f->starved = true;
    return false;
}

/* ---- transforms ------------------------------------------------------------------------------- */

static void xf_identity(nff_xf *x) {
    static const float id[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    static const float id3[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    memcpy(x->m, id, sizeof id);
    memcpy(x->nm, id3, sizeof id3);
    x->scale = 1.0f;
    x->identity = true;
}

/* Normal matrix and radius scale from the 3x3 part. */
static void xf_finish(nff_xf *x) {
    const float *m = x->m;
    float a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
    /* Cofactor matrix = det * inverse transpose; the sign of det keeps normals on their side. */
    float co[9] = {e * i - f * h, f * g - d * i, d * h - e * g, c * h - b * i, a * i - c * g,
                   b * g - a * h, b * f - c * e, c * d - a * f, a * e - b * d};
    float det = a * co[0] + b * co[1] + c * co[2];
    float s = det < 0.0f ? -1.0f : 1.0f;
    for (int k = 0; k < 9; k++) x->nm[k] = s * co[k];
    float cx = sqrtf(a * a + d * d + g * g), cy = sqrtf(b * b + e * e + h * h), cz = sqrtf(c * c + f * f + i * i);
    x->scale = fmaxf(cx, fmaxf(cy, cz));
    static const float id[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    x->identity = memcmp(x->m, id, sizeof id) == 0;
}

/* out = a * b (3x4 affine). */
static void xf_mul(const float *a, const float *b, float *out) {
    float r[12];
    for (int row = 0; row < 3; row++) {
        for (int col = 0; col < 4; col++) {
            float v = a[4 * row] * b[col] + a[4 * row + 1] * b[4 + col] + a[4 * row + 2] * b[8 + col];
            if (col == 3) v += a[4 * row + 3];
            r[4 * row + col] = v;
        }
    }
    memcpy(out, r, sizeof r);
}

/* T * R * S, the order BART composes both static and keyframed transforms in. */
static void xf_trs(const float t[3], const float axis[3], float deg, const float s[3], float *out) {
    float x = axis[0], y = axis[1], z = axis[2];
    float len = sqrtf(x * x + y * y + z * z);
    float r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    if (len > 0.0f && deg != 0.0f) {
        x /= len, y /= len, z /= len;
        float rad = deg * 3.14159265358979323846f / 180.0f;
        float c = cosf(rad), sn = sinf(rad), k = 1.0f - c;
        float rr[9] = {c + x * x * k,     x * y * k - z * sn, x * z * k + y * sn,
                       y * x * k + z * sn, c + y * y * k,     y * z * k - x * sn,
                       z * x * k - y * sn, z * y * k + x * sn, c + z * z * k};
        memcpy(r, rr, sizeof r);
    }
    for (int row = 0; row < 3; row++) {
        for (int col = 0; col < 3; col++) out[4 * row + col] = r[3 * row + col] * s[col];
        out[4 * row + 3] = t[row];
    }
}

static inline void xf_point(const nff_xf *x, float *p) {
    const float *m = x->m;
    float v[3] = {p[0], p[1], p[2]};
    for (int r = 0; r < 3; r++) p[r] = m[4 * r] * v[0] + m[4 * r + 1] * v[1] + m[4 * r + 2] * v[2] + m[4 * r + 3];
}

static inline void xf_normal(const nff_xf *x, float *n) {
    const float *m = x->nm;
    float v[3] = {n[0], n[1], n[2]};
    for (int r = 0; r < 3; r++) n[r] = m[3 * r] * v[0] + m[3 * r + 1] * v[1] + m[3 * r + 2] * v[2];
    float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (len > 0.0f) n[0] /= len, n[1] /= len, n[2] /= len;
}

static const nff_xf *nff_top(const nff_file *f) { return &f->st->stack[f->st->depth].xf; }

/* ---- materials and textures ------------------------------------------------------------------- */

static uint32_t nff_material(nff_file *f) {
    if (f->st->material == IO_NONE) return builder_default_material(f->ctx);
    return f->st->material;
}

static bool nff_add_material(nff_file *f, rp_material_data *m) {
    snprintf(m->name, sizeof m->name, "f%zu", f->st->f_count++);
    if (m->ior <= 0.0f) m->ior = 1.0f; /* BART files write 0 for "no refraction" */
    uint32_t k = builder_add_material(f->ctx, m);
    if (k == IO_NONE) return io_error(f->ctx, f->shown, f->line, "out of memory");
    f->st->material = k;
    return true;
}

/* Texture named in an AFF file. BART keeps them in TextureFiles/ beside aff/, so the lookup tries
 * the file's folder, then ../TextureFiles/ and TextureFiles/, then (in an archive) the one entry of
 * that base name. */
static uint32_t nff_texture(nff_file *f, const char *name) {
    io_ctx *ctx = f->ctx;
    char rel[IO_PATH_MAX], full[IO_PATH_MAX], first[IO_PATH_MAX];
    const char *tries[3] = {"%s", "../TextureFiles/%s", "TextureFiles/%s"};
    for (int i = 0; i < 3; i++) {
        snprintf(rel, sizeof rel, tries[i], name);
        vfs_join(&ctx->vfs, f->path, rel, full, sizeof full);
        if (i == 0) memcpy(first, full, sizeof first);
        if (vfs_exists(ctx, full)) return tex_load(ctx, full, name, f->shown, f->line);
    }
    if (ctx->vfs.archive) {
        const char *slash = strrchr(name, '/');
        const char *found = vfs_find_basename(&ctx->vfs, slash ? slash + 1 : name);
        if (found) return tex_load(ctx, found, name, f->shown, f->line);
    }
    return tex_load(ctx, first, name, f->shown, f->line); /* fails with the error naming it */
}

/* The current material with a diffuse texture: one material per (material, texture) pair. */
static uint32_t nff_textured_material(nff_file *f, const char *tex_name) {
    uint32_t tex = nff_texture(f, tex_name);
    if (tex == IO_NONE) return IO_NONE;
    uint32_t base = nff_material(f);
    if (base == IO_NONE) {
        io_error(f->ctx, f->shown, f->line, "out of memory");
        return IO_NONE;
    }
    nff_state *st = f->st;
    for (size_t i = 0; i < st->tex_mat_n; i++)
        if (st->tex_mats[i][0] == base && st->tex_mats[i][1] == tex) return st->tex_mats[i][2];
    rp_material_data m = f->ctx->b.materials[base];
    m.map_kd = (int32_t)tex;
    uint32_t k = builder_add_material(f->ctx, &m);
    if (k == IO_NONE || !io_reserve((void **)&st->tex_mats, &st->tex_mat_cap, st->tex_mat_n + 1, sizeof st->tex_mats[0])) {
        io_error(f->ctx, f->shown, f->line, "out of memory");
        return IO_NONE;
    }
    st->tex_mats[st->tex_mat_n][0] = base;
    st->tex_mats[st->tex_mat_n][1] = tex;
    st->tex_mats[st->tex_mat_n][2] = k;
    st->tex_mat_n++;
    return k;
}

/* ---- primitives ------------------------------------------------------------------------------- */

/* Reads n vertices (xyz, then normal and uv when asked) straight into the builder, transformed. */
static bool nff_vertices(nff_file *f, size_t n, bool normals, bool uvs, const char *what) {
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    if (b->pos_n + n >= UINT32_MAX || !builder_reserve_vertices(ctx, n) ||
        (normals && !builder_reserve_normals(ctx, n)) || (uvs && !builder_reserve_texcoords(ctx, n)))
        return io_error(ctx, f->shown, f->line, "out of memory");
    const nff_xf *x = nff_top(f);
    for (size_t i = 0; i < n; i++) {
        float *p = b->pos + 3 * (b->pos_n + i);
        if (!nff_floats(f, p, 3, what)) return false;
        if (!x->identity) xf_point(x, p);
        if (normals) {
            float *nn = b->nrm + 3 * (b->nrm_n + i);
            if (!nff_floats(f, nn, 3, what)) return false;
            if (!x->identity) xf_normal(x, nn);
        }
        if (uvs && !nff_floats(f, b->uv + 2 * (b->uv_n + i), 2, what)) return false;
    }
    return true;
}

/* Emits the polygon whose n vertices were just read (not yet counted in the builder). */
static bool nff_polygon(nff_file *f, uint32_t n, bool normals, bool uvs, uint32_t material) {
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    uint32_t v0 = (uint32_t)b->pos_n, n0 = (uint32_t)b->nrm_n, t0 = (uint32_t)b->uv_n;
    uint32_t tri_buf[3 * 2 + 4], *tris = tri_buf, *ring = tri_buf + 6;
    if (n > 4) {
        uint32_t *s = io_scratch_u(ctx, 4 * (size_t)n);
        if (!s) return io_error(ctx, f->shown, f->line, "out of memory");
        tris = s;
        ring = s + 3 * (n - 2);
    }
    poly_triangulate(b->pos + 3 * (size_t)v0, n, tris, ring);
    b->pos_n += n;
    if (normals) b->nrm_n += n;
    if (uvs) b->uv_n += n;
    if (!builder_reserve_triangles(ctx, n - 2)) return io_error(ctx, f->shown, f->line, "out of memory");
    for (uint32_t k = 0; k < n - 2; k++) {
        const uint32_t *t = tris + 3 * k;
        uint32_t v[3] = {v0 + t[0], v0 + t[1], v0 + t[2]};
        uint32_t nn[3] = {n0 + t[0], n0 + t[1], n0 + t[2]};
        uint32_t tt[3] = {t0 + t[0], t0 + t[1], t0 + t[2]};
        if (!builder_add_triangle(ctx, v, normals ? nn : NULL, uvs ? tt : NULL, material))
            return io_error(ctx, f->shown, f->line, "out of memory");
    }
    return true;
}

/* `p n` / `pp n`: a polygon, with a normal per vertex for `pp`. */
static bool nff_poly(nff_file *f, bool patch) {
    int64_t n;
    const char *what = patch ? "pp" : "p";
    if (!nff_int(f, &n, what)) return false;
    if (n < 3) return io_error(f->ctx, f->shown, f->line, "%s: polygon with %lld vertices (at least 3 needed)", what, (long long)n);
    /* Every vertex takes at least 6 bytes of text: a larger count is a truncated or lying file. */
    if ((uint64_t)n > (uint64_t)(f->end - f->p) / 6 + 1) {
        f->p = f->end;
        return nff_eof_error(f, "polygon vertices");
    }
    uint32_t material = nff_material(f);
    if (material == IO_NONE) return io_error(f->ctx, f->shown, f->line, "out of memory");
    return nff_vertices(f, (size_t)n, patch, false, what) && nff_polygon(f, (uint32_t)n, patch, false, material);
}

/* `tt tex` / `ttp tex`: a textured triangle (ttp with normals). */
static bool nff_textured_triangle(nff_file *f, bool patch) {
    char tex[256];
    if (!nff_word(f, tex, sizeof tex, "texture name")) return false;
    uint32_t material = nff_textured_material(f, tex);
    if (material == IO_NONE) return false;
    return nff_vertices(f, 3, patch, true, patch ? "ttp" : "tt") && nff_polygon(f, 3, patch, true, material);
}

/* `tpa n`: a triangle keyframed n times (time, then 3 x position and normal); the corners at the
 * first key go into the mesh, every key (in the transform's space) into the animation. */
static bool nff_animated_triangle(nff_file *f) {
    nff_state *st = f->st;
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    int64_t n;
    if (!nff_int(f, &n, "tpa")) return false;
    if (n < 1 || !nff_fits(f, n, 38)) {
        if (f->starved) return false;
        return io_error(ctx, f->shown, f->line, "tpa: bad keyframe count %lld (at least 1)", (long long)n);
    }
    uint32_t line = f->line;
    if (!io_reserve((void **)&st->tpa_keys, &st->tpak_cap, st->tpak_n + 19 * (size_t)n, sizeof(float)) ||
        !io_reserve((void **)&st->tpas, &st->tpa_cap, st->tpa_n + 1, sizeof(rp_anim_tpa)))
        return io_error(ctx, f->shown, f->line, "out of memory");
    float *keys = st->tpa_keys + st->tpak_n;
    const nff_xf *x = nff_top(f);
    for (int64_t k = 0; k < n; k++) {
        float *v = keys + 19 * k;
        if (!nff_floats(f, v, 19, "tpa")) return false;
        if (k > 0 && !(v[0] >= v[-19]))
            return io_error(ctx, f->shown, f->line, "tpa: keyframe time %g before the previous one (%g)", (double)v[0],
                            (double)v[-19]);
        for (int c = 0; c < 3 && !x->identity; c++) {
            xf_point(x, v + 1 + 6 * c);
            xf_normal(x, v + 4 + 6 * c);
        }
    }
    uint32_t material = nff_material(f);
    if (material == IO_NONE) return io_error(ctx, f->shown, line, "out of memory");
    if (b->pos_n + 3 >= UINT32_MAX || !builder_reserve_vertices(ctx, 3) || !builder_reserve_normals(ctx, 3))
        return io_error(ctx, f->shown, line, "out of memory");
    for (int c = 0; c < 3; c++) {
        memcpy(b->pos + 3 * (b->pos_n + (size_t)c), keys + 1 + 6 * c, 3 * sizeof(float));
        memcpy(b->nrm + 3 * (b->nrm_n + (size_t)c), keys + 4 + 6 * c, 3 * sizeof(float));
    }
    rp_anim_tpa *t = &st->tpas[st->tpa_n];
    t->triangle = (uint32_t)b->tri_n, t->vertex = (uint32_t)b->pos_n, t->normal = (uint32_t)b->nrm_n;
    t->first = (uint32_t)(st->tpak_n / 19), t->count = (uint32_t)n;
    uint32_t here = f->line;
    f->line = line;
    bool ok = nff_polygon(f, 3, true, false, material);
    f->line = here;
    if (!ok) return false;
    if (b->tri_n != (size_t)t->triangle + 1) return true; /* degenerate corners: no triangle to move */
    st->tpak_n += 19 * (size_t)n;
    st->tpa_n++;
    return true;
}

static bool nff_sphere(nff_file *f) {
    float v[4];
    if (!nff_floats(f, v, 4, "s")) return false;
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    uint32_t material = nff_material(f);
    if (material == IO_NONE || !io_reserve((void **)&b->spheres, &b->sphere_cap, b->sphere_n + 1, sizeof(rp_sphere_data)))
        return io_error(ctx, f->shown, f->line, "out of memory");
    const nff_xf *x = nff_top(f);
    rp_sphere_data *s = &b->spheres[b->sphere_n++];
    memcpy(s->center, v, sizeof s->center);
    xf_point(x, s->center);
    s->radius = fabsf(v[3]) * x->scale; /* negative: seen from inside; the renderer takes both sides */
    s->material = material;
    return true;
}

static bool nff_cone(nff_file *f) {
    float v[8];
    if (!nff_floats(f, v, 8, "c")) return false;
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    uint32_t material = nff_material(f);
    if (material == IO_NONE || !io_reserve((void **)&b->cones, &b->cone_cap, b->cone_n + 1, sizeof(rp_cone_data)))
        return io_error(ctx, f->shown, f->line, "out of memory");
    const nff_xf *x = nff_top(f);
    rp_cone_data *c = &b->cones[b->cone_n++];
    memcpy(c->base, v, sizeof c->base);
    memcpy(c->apex, v + 4, sizeof c->apex);
    xf_point(x, c->base);
    xf_point(x, c->apex);
    c->base_radius = fabsf(v[3]) * x->scale;
    c->apex_radius = fabsf(v[7]) * x->scale;
    c->material = material;
    return true;
}

static bool nff_light(nff_file *f, bool animated) {
    char name[64];
    if (animated && !nff_word(f, name, sizeof name, "la name")) return false;
    rp_light_data l;
    memset(&l, 0, sizeof l);
    l.type = RP_LIGHT_DATA_POINT;
    l.color[0] = l.color[1] = l.color[2] = 1.0f;
    if (!nff_floats(f, l.position, 3, "l")) return false;
    bool colour = nff_number_next(f);
    if (f->starved || (colour && !nff_floats(f, l.color, 3, "l colour"))) return false;
    if (!nff_nonnegative(f, l.color, 0, 3, "l colour")) return false;
    xf_point(nff_top(f), l.position);
    io_builder *b = &f->ctx->b;
    if (!io_reserve((void **)&b->lights, &b->light_cap, b->light_n + 1, sizeof l))
        return io_error(f->ctx, f->shown, f->line, "out of memory");
    b->lights[b->light_n++] = l;
    return true;
}

/* `f r g b Kd Ks Shine T ior`: kd = colour * Kd, ks = kr = Ks, kt = T. */
static bool nff_fill(nff_file *f) {
    float v[8];
    if (!nff_floats(f, v, 8, "f") || !nff_nonnegative(f, v, 0, 5, "f") || !nff_nonnegative(f, v, 6, 1, "f")) return false;
    rp_material_data m;
    builder_material_defaults(&m, "");
    for (int i = 0; i < 3; i++) {
        m.kd[i] = v[i] * v[3];
        m.ks[i] = m.kr[i] = v[4];
        m.kt[i] = v[6];
    }
    m.ns = v[5];
    m.ior = v[7];
    return nff_add_material(f, &m);
}

/* `fm amb(3) diff(3) spec(3) Shine T ior` (AFF): ka = amb, ks = kr = spec, kt = T. */
static bool nff_fill_material(nff_file *f) {
    float v[12];
    if (!nff_floats(f, v, 12, "fm") || !nff_nonnegative(f, v, 0, 9, "fm") || !nff_nonnegative(f, v, 10, 1, "fm"))
        return false;
    rp_material_data m;
    builder_material_defaults(&m, "");
    for (int i = 0; i < 3; i++) {
        m.ka[i] = v[i];
        m.kd[i] = v[3 + i];
        m.ks[i] = m.kr[i] = v[6 + i];
        m.kt[i] = v[10];
    }
    m.ns = v[9];
    m.ior = v[11];
    return nff_add_material(f, &m);
}

static bool nff_viewpoint(nff_file *f) {
    rp_camera_data *cam = &f->ctx->b.camera;
    memset(cam, 0, sizeof *cam);
    float angle = 45.0f;
    unsigned seen = 0;
    uint32_t line_at = f->line, line_up = f->line;
    for (;;) {
        nff_skip(f);
        if (f->p >= f->end && f->more) return nff_eof_error(f, "viewpoint");
        const char *p = f->p;
        size_t n = 0;
        while (!nff_delim(p[n])) n++;
#define NFF_IS(w) (n == sizeof(w) - 1 && memcmp(p, w, n) == 0)
        if (NFF_IS("from")) {
            f->p += n;
            if (!nff_floats(f, cam->eye, 3, "from")) return false;
            seen |= 1;
        } else if (NFF_IS("at")) {
            f->p += n;
            line_at = f->line;
            if (!nff_floats(f, cam->look, 3, "at")) return false;
            seen |= 2;
        } else if (NFF_IS("up")) {
            f->p += n;
            line_up = f->line;
            if (!nff_floats(f, cam->up, 3, "up")) return false;
            seen |= 4;
        } else if (NFF_IS("angle")) {
            f->p += n;
            if (!nff_float(f, &angle, "angle")) return false;
            seen |= 8;
        } else if (NFF_IS("hither")) {
            float hither;
            f->p += n;
            if (!nff_float(f, &hither, "hither")) return false;
        } else if (NFF_IS("resolution")) {
            int64_t w, h;
            f->p += n;
            if (!nff_int(f, &w, "resolution") || !nff_int(f, &h, "resolution")) return false;
            if (w <= 0 || h <= 0 || w > 1 << 16 || h > 1 << 16)
                return io_error(f->ctx, f->shown, f->line, "resolution %lld x %lld out of range", (long long)w, (long long)h);
            cam->width = (int32_t)w;
            cam->height = (int32_t)h;
        } else {
            break;
        }
#undef NFF_IS
    }
    if (seen != 15) return io_error(f->ctx, f->shown, f->line, "viewpoint needs from, at, up and angle");
    /* A camera the renderer cannot form (DESIGN.md's frame from look - eye and up) is the file's
     * error, at the line that made it so, not a uniform image. */
    float d[3] = {cam->look[0] - cam->eye[0], cam->look[1] - cam->eye[1], cam->look[2] - cam->eye[2]};
    double dd = 0.0, uu = 0.0, cc = 0.0;
    for (int k = 0; k < 3; k++) {
        if (!isfinite(d[k])) return io_error(f->ctx, f->shown, line_at, "viewpoint: 'at' - 'from' overflows");
        dd += (double)d[k] * d[k];
        uu += (double)cam->up[k] * cam->up[k];
        int a = (k + 1) % 3, b = (k + 2) % 3;
        double c = (double)d[a] * cam->up[b] - (double)d[b] * cam->up[a];
        cc += c * c;
    }
    if (!(dd > 0.0)) return io_error(f->ctx, f->shown, line_at, "viewpoint: 'from' and 'at' are the same point");
    if (!(uu > 0.0)) return io_error(f->ctx, f->shown, line_up, "viewpoint: 'up' is the zero vector");
    if (!(cc > 1e-10 * dd * uu))
        return io_error(f->ctx, f->shown, line_up, "viewpoint: 'up' is parallel to the view direction (from -> at)");
    if (!(angle > 0.0f && angle < 180.0f)) return io_error(f->ctx, f->shown, f->line, "view angle %g out of (0, 180)", (double)angle);
    /* NFF's angle spans the smaller image side: the vertical fov unless the image is portrait. */
    float fov = angle;
    if (cam->width > 0 && cam->height > cam->width) {
        double half = tan((double)angle * 3.14159265358979323846 / 360.0) * cam->height / cam->width;
        fov = (float)(atan(half) * 360.0 / 3.14159265358979323846);
    }
    cam->fov_deg = fov;
    cam->valid = true;
    return true;
}

/* `m`: an indexed triangle mesh with optional normals and texture coordinates. */
static bool nff_mesh(nff_file *f) {
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    char word[64];
    int64_t nv, nn = 0, nt = 0, ntri;
    if (!nff_word(f, word, sizeof word, "mesh 'vertices'")) return false;
    if (strcmp(word, "vertices") != 0) return io_error(ctx, f->shown, f->line, "mesh: expected 'vertices', got '%s'", word);
    if (!nff_int(f, &nv, "vertices")) return false;
    if (nv < 0 || !nff_fits(f, nv, 6)) return f->starved ? false : io_error(ctx, f->shown, f->line, "mesh: bad vertex count %lld", (long long)nv);
    size_t v0 = b->pos_n, n0 = b->nrm_n, t0 = b->uv_n;
    if (!nff_vertices(f, (size_t)nv, false, false, "mesh vertex")) return false;
    b->pos_n += (size_t)nv;
    if (!nff_word(f, word, sizeof word, "mesh 'normals', 'texturecoords' or 'triangles'")) return false;
    if (strcmp(word, "normals") == 0) {
        if (!nff_int(f, &nn, "normals")) return false;
        if (nn < 0 || !nff_fits(f, nn, 6) || b->nrm_n + (size_t)nn >= UINT32_MAX ||
            !builder_reserve_normals(ctx, (size_t)nn))
            return f->starved ? false : io_error(ctx, f->shown, f->line, "mesh: bad normal count %lld", (long long)nn);
        const nff_xf *x = nff_top(f);
        for (int64_t i = 0; i < nn; i++) {
            float *v = b->nrm + 3 * b->nrm_n;
            if (!nff_floats(f, v, 3, "mesh normal")) return false;
            if (!x->identity) xf_normal(x, v);
            b->nrm_n++;
        }
        if (!nff_word(f, word, sizeof word, "mesh 'texturecoords' or 'triangles'")) return false;
    }
    uint32_t material = nff_material(f);
    if (strcmp(word, "texturecoords") == 0) {
        char tex[256];
        if (!nff_int(f, &nt, "texturecoords")) return false;
        if (!nff_word(f, tex, sizeof tex, "texture name")) return false;
        if (nt < 0 || !nff_fits(f, nt, 4) || b->uv_n + (size_t)nt >= UINT32_MAX ||
            !builder_reserve_texcoords(ctx, (size_t)nt))
            return f->starved ? false : io_error(ctx, f->shown, f->line, "mesh: bad texture coordinate count %lld", (long long)nt);
        uint32_t line = f->line;
        for (int64_t i = 0; i < nt; i++) {
            if (!nff_floats(f, b->uv + 2 * b->uv_n, 2, "mesh texture coordinate")) return false;
            b->uv_n++;
        }
        uint32_t here = f->line;
        f->line = line; /* a missing texture is reported on the line naming it */
        material = nff_textured_material(f, tex);
        f->line = here;
        if (material == IO_NONE) return false;
        if (!nff_word(f, word, sizeof word, "mesh 'triangles'")) return false;
    }
    if (material == IO_NONE) return io_error(ctx, f->shown, f->line, "out of memory");
    if (strcmp(word, "triangles") != 0) return io_error(ctx, f->shown, f->line, "mesh: expected 'triangles', got '%s'", word);
    if (!nff_int(f, &ntri, "triangles")) return false;
    if (ntri < 0 || !nff_fits(f, ntri, 6))
        return f->starved ? false : io_error(ctx, f->shown, f->line, "mesh: bad triangle count %lld", (long long)ntri);
    if (!builder_reserve_triangles(ctx, (size_t)ntri)) return io_error(ctx, f->shown, f->line, "out of memory");
    /* Per triangle: vertex indices, then normal indices, then texture coordinate indices. */
    for (int64_t k = 0; k < ntri; k++) {
        int64_t raw[9];
        int m = 3 + (nn ? 3 : 0) + (nt ? 3 : 0);
        for (int j = 0; j < m; j++)
            if (!nff_int(f, &raw[j], "mesh triangle index")) return false;
        uint32_t v[3], n[3], t[3];
        for (int j = 0; j < 3; j++) {
            int64_t iv = raw[j], in = nn ? raw[3 + j] : 0, it = nt ? raw[(nn ? 6 : 3) + j] : 0;
            if (iv < 0 || iv >= nv || in < 0 || (nn && in >= nn) || it < 0 || (nt && it >= nt))
                return io_error(ctx, f->shown, f->line, "mesh triangle %lld: index out of range (%lld vertices, %lld normals, %lld texture coordinates)",
                                (long long)k, (long long)nv, (long long)nn, (long long)nt);
            v[j] = (uint32_t)(v0 + (size_t)iv);
            n[j] = (uint32_t)(n0 + (size_t)in);
            t[j] = (uint32_t)(t0 + (size_t)it);
        }
        if (!builder_add_triangle(ctx, v, nn ? n : NULL, nt ? t : NULL, material))
            return io_error(ctx, f->shown, f->line, "out of memory");
    }
    return true;
}

/* `xs sx sy sz  rx ry rz deg  tx ty tz {` and `x name {`. */
static bool nff_transform(nff_file *f, bool is_static) {
    nff_state *st = f->st;
    io_builder *b = &f->ctx->b;
    if (st->depth >= NFF_MAX_DEPTH) return io_error(f->ctx, f->shown, f->line, "transforms nested too deep");
    nff_level *parent = &st->stack[st->depth], *lv = &st->stack[st->depth + 1];
    lv->line = f->line;
    lv->file = f->path;
    lv->anim = -1;
    if (is_static) {
        float v[10], local[12];
        if (!nff_floats(f, v, 10, "xs")) return false;
        xf_trs(v + 7, v + 3, v[6], v, local);
        xf_mul(parent->xf.m, local, lv->xf.m);
        xf_finish(&lv->xf);
    } else {
        char name[64];
        if (!nff_word(f, name, sizeof name, "x name")) return false;
        if (!io_reserve((void **)&st->anims, &st->anim_cap, st->anim_n + 1, sizeof(nff_anim_node)))
            return io_error(f->ctx, f->shown, f->line, "out of memory");
        nff_anim_node *a = &st->anims[st->anim_n];
        memset(a, 0, sizeof *a);
        snprintf(a->name, sizeof a->name, "%s", name);
        a->parent = parent->xf;
        a->parent_node = -1;
        for (int d = st->depth; d > 0 && a->parent_node < 0; d--) a->parent_node = st->stack[d].anim;
        a->tri0 = b->tri_n, a->sph0 = b->sphere_n, a->cone0 = b->cone_n, a->light0 = b->light_n;
        lv->xf = parent->xf;
        lv->anim = (int)st->anim_n++;
    }
    if (!nff_expect(f, '{', is_static ? "xs" : "x")) return false;
    st->depth++;
    return true;
}

static bool nff_close(nff_file *f) {
    nff_state *st = f->st;
    if (st->depth == 0) return io_error(f->ctx, f->shown, f->line, "'}' without an open transform");
    nff_level *lv = &st->stack[st->depth];
    if (lv->anim >= 0) {
        io_builder *b = &f->ctx->b;
        nff_anim_node *a = &st->anims[lv->anim];
        a->tri1 = b->tri_n, a->sph1 = b->sphere_n, a->cone1 = b->cone_n, a->light1 = b->light_n;
    }
    st->depth--;
    return true;
}

/* `k name { transl n ... rot n ... scale n ... visibility n ... }`: each channel once, at least 4
 * spline keys (BART: the first and last only shape the tangents), times never decreasing. */
static bool nff_keyframes(nff_file *f) {
    nff_state *st = f->st;
    io_ctx *ctx = f->ctx;
    char name[64], word[64];
    if (!nff_word(f, name, sizeof name, "k name") || !nff_expect(f, '{', "k name")) return false;
    /* a name keyed again (a file included twice) replaces the earlier keys, as BART's lookup finds
     * the last animation of a name */
    nff_keys *k = NULL;
    for (size_t i = 0; i < st->key_n; i++)
        if (strcmp(st->keys[i].name, name) == 0) k = &st->keys[i];
    if (!k) {
        if (!io_reserve((void **)&st->keys, &st->key_cap, st->key_n + 1, sizeof(nff_keys)))
            return io_error(ctx, f->shown, f->line, "out of memory");
        k = &st->keys[st->key_n++];
    } else if (f->more) { /* kept for nff_undo, should this block starve */
        f->saved_key = *k;
        f->saved_key_at = (size_t)(k - st->keys);
    }
    memset(k, 0, sizeof *k);
    snprintf(k->name, sizeof k->name, "%s", name);
    bool seen[4] = {false, false, false, false};
    for (;;) {
        nff_skip(f);
        if (f->p >= f->end) return nff_eof_error(f, "'}' closing the keyframes");
        if (*f->p == '}') {
            f->p++;
            return true;
        }
        int64_t n;
        if (!nff_word(f, word, sizeof word, "keyframe type")) return false;
        uint32_t line = f->line;
        if (!nff_int(f, &n, "keyframe count")) return false;
        int ch;
        if (strcmp(word, "transl") == 0) ch = RP_ANIM_TRANSL;
        else if (strcmp(word, "rot") == 0) ch = RP_ANIM_ROT;
        else if (strcmp(word, "scale") == 0) ch = RP_ANIM_SCALE;
        else if (strcmp(word, "visibility") == 0) ch = 3;
        else return io_error(ctx, f->shown, line, "unknown keyframe type '%s' (transl, rot, scale, visibility)", word);
        if (seen[ch]) return io_error(ctx, f->shown, line, "'%s' keyframes given twice for '%s'", word, name);
        seen[ch] = true;
        int64_t least = ch == 3 ? 1 : 4;
        if (n < least || !nff_fits(f, n, 4)) {
            if (f->starved) return false;
            return io_error(ctx, f->shown, line, "%s: %lld keyframes (at least %lld%s)", word, (long long)n, (long long)least,
                            ch == 3 ? "" : ": the first and last only shape the spline's ends");
        }
        float prev = -INFINITY;
        if (ch == 3) {
            if (!io_reserve((void **)&st->vis_t, &st->vis_cap, st->vis_n + (size_t)n, sizeof(float)) ||
                !io_reserve((void **)&st->vis_v, &st->vis_cap2, st->vis_n + (size_t)n, 1))
                return io_error(ctx, f->shown, f->line, "out of memory");
            k->vis_first = (uint32_t)st->vis_n, k->vis_count = (uint32_t)n;
            for (int64_t i = 0; i < n; i++) {
                float t = 0.0f;
                int64_t v = 0;
                if (!nff_float(f, &t, "visibility time") || !nff_int(f, &v, "visibility flag")) return false;
                if (v != 0 && v != 1) return io_error(ctx, f->shown, f->line, "visibility flag %lld (0 or 1)", (long long)v);
                if (!(t >= prev)) return io_error(ctx, f->shown, f->line, "visibility: time %g before the previous key's", (double)t);
                prev = t;
                st->vis_t[st->vis_n] = t, st->vis_v[st->vis_n++] = (uint8_t)v;
            }
            continue;
        }
        if (!io_reserve((void **)&st->akeys, &st->akey_cap, st->akey_n + (size_t)n, sizeof(rp_anim_key)))
            return io_error(ctx, f->shown, f->line, "out of memory");
        k->track[ch].first = (uint32_t)st->akey_n, k->track[ch].count = (uint32_t)n;
        int per = ch == RP_ANIM_ROT ? 8 : 7;
        for (int64_t i = 0; i < n; i++) {
            float v[8];
            if (!nff_floats(f, v, per, word)) return false;
            if (!(v[0] >= prev))
                return io_error(ctx, f->shown, f->line, "%s: keyframe time %g before the previous one (%g)", word, (double)v[0],
                                (double)prev);
            prev = v[0];
            rp_anim_key *key = &st->akeys[st->akey_n++];
            memset(key, 0, sizeof *key);
            key->time = v[0];
            memcpy(key->value, v + 1, (size_t)(per - 4) * sizeof(float));
            key->tension = v[per - 3], key->continuity = v[per - 2], key->bias = v[per - 1];
            if (ch == RP_ANIM_ROT && !(v[1] * v[1] + v[2] * v[2] + v[3] * v[3] > 0.0f))
                return io_error(ctx, f->shown, f->line, "rot: the rotation axis is the zero vector");
        }
    }
}

/* The parsed animation for io_anim.c: nodes with their keys looked up by name, `k camera`, the
 * innermost node of every triangle, sphere, cone and light, the `tpa` keys and the `a` range. A
 * scene without keys, `tpa` or camera path stays still (no animation). */
static bool nff_animation(io_ctx *ctx, nff_state *st, const char *shown) {
    const nff_keys *cam = NULL;
    for (size_t i = 0; i < st->key_n; i++)
        if (strcmp(st->keys[i].name, "camera") == 0) cam = &st->keys[i];
    bool keyed = cam != NULL || st->tpa_n > 0;
    for (size_t ai = 0; ai < st->anim_n && !keyed; ai++)
        for (size_t i = 0; i < st->key_n; i++)
            if (strcmp(st->keys[i].name, st->anims[ai].name) == 0) keyed = true;
    if (!keyed) return true;
    io_builder *b = &ctx->b;
    rp_animation_data *a = calloc(1, sizeof *a);
    if (!a) return io_error(ctx, shown, 0, "out of memory");
    ctx->anim = a;
    a->node_count = st->anim_n;
    a->nodes = calloc(st->anim_n + 1, sizeof *a->nodes);
    a->tri_node = malloc((b->tri_n + 1) * sizeof *a->tri_node);
    a->sphere_node = malloc((b->sphere_n + 1) * sizeof(int32_t));
    a->cone_node = malloc((b->cone_n + 1) * sizeof(int32_t));
    a->light_node = malloc((b->light_n + 1) * sizeof(int32_t));
    if (!a->nodes || !a->tri_node || !a->sphere_node || !a->cone_node || !a->light_node)
        return io_error(ctx, shown, 0, "out of memory");
    for (size_t i = 0; i < b->tri_n; i++) a->tri_node[i] = -1;
    for (size_t i = 0; i < b->sphere_n; i++) a->sphere_node[i] = -1;
    for (size_t i = 0; i < b->cone_n; i++) a->cone_node[i] = -1;
    for (size_t i = 0; i < b->light_n; i++) a->light_node[i] = -1;
    /* blocks in the order they opened: an inner block's range lies inside its parent's and
     * overwrites it, so every element ends with its innermost block */
    for (size_t ai = 0; ai < st->anim_n; ai++) {
        const nff_anim_node *s = &st->anims[ai];
        rp_anim_node *n = &a->nodes[ai];
        snprintf(n->name, sizeof n->name, "%s", s->name);
        n->parent = s->parent_node;
        memcpy(n->rest, s->parent.m, sizeof n->rest);
        double rest[12], inv[12]; /* as rp_scene_data_set_time inverts it */
        for (int j = 0; j < 12; j++) rest[j] = n->rest[j];
        if (!anim_inverse(rest, inv)) return io_error(ctx, shown, 0, "singular transform around keyframed block '%s'", s->name);
        for (size_t i = 0; i < st->key_n; i++) {
            if (strcmp(st->keys[i].name, s->name) != 0) continue;
            memcpy(n->track, st->keys[i].track, sizeof n->track);
            n->vis_first = st->keys[i].vis_first, n->vis_count = st->keys[i].vis_count;
        }
        for (size_t i = s->tri0; i < s->tri1; i++) a->tri_node[i] = (int32_t)ai;
        for (size_t i = s->sph0; i < s->sph1; i++) a->sphere_node[i] = (int32_t)ai;
        for (size_t i = s->cone0; i < s->cone1; i++) a->cone_node[i] = (int32_t)ai;
        for (size_t i = s->light0; i < s->light1; i++) a->light_node[i] = (int32_t)ai;
    }
    if (cam) {
        a->camera[RP_ANIM_TRANSL] = cam->track[RP_ANIM_TRANSL];
        a->camera[RP_ANIM_ROT] = cam->track[RP_ANIM_ROT];
    }
    a->keys = st->akeys, a->key_count = st->akey_n;
    st->akeys = NULL;
    a->vis_times = st->vis_t, a->vis_values = st->vis_v, a->vis_count = st->vis_n;
    st->vis_t = NULL, st->vis_v = NULL;
    a->tpas = st->tpas, a->tpa_count = st->tpa_n;
    a->tpa_keys = st->tpa_keys;
    st->tpas = NULL, st->tpa_keys = NULL;
    if (st->has_range) {
        a->start = st->start, a->end = st->end, a->frames = st->frames;
    } else { /* no `a` line: the keys' range, one frame per key interval */
        float lo = INFINITY, hi = -INFINITY;
        for (size_t i = 0; i < a->key_count; i++) lo = fminf(lo, a->keys[i].time), hi = fmaxf(hi, a->keys[i].time);
        for (size_t i = 0; i < a->tpa_count; i++) {
            const float *k = a->tpa_keys + 19 * (size_t)a->tpas[i].first;
            lo = fminf(lo, k[0]), hi = fmaxf(hi, k[19 * ((size_t)a->tpas[i].count - 1)]);
        }
        if (!(lo <= hi)) lo = hi = 0.0f;
        a->start = lo, a->end = hi, a->frames = hi > lo ? 2 : 1;
    }
    return true;
}

/* ---- parallel polygon lists ------------------------------------------------------------------- */

/* A large file's polygon lists (`p`, `pp` and `f`: nearly all of an SPD file) are parsed in chunks
 * on several threads, each chunk by the serial functions above into a builder of its own, then
 * appended in file order. A chunk starts at a line that begins with `p`, `pp` or `f`; that is a
 * guess (such a line could be a texture or block name inside another command), so the serial pass
 * takes a chunk only when it reaches exactly that start as a command, with no transform block open
 * (chunks are parsed under the identity), and parses on by itself from wherever a chunk stopped:
 * at a command chunks leave to it, or at an error, whose message it then writes with the file's own
 * line number. The result, errors included, is the serial one to the bit. */

typedef struct nff_chunk {
    const char *start, *limit; /* parses commands from start until one begins at or after limit */
    const char *stop;          /* the first command it did not parse */
    uint32_t lines;            /* newlines from start to stop */
    io_ctx ctx;                /* the chunk's builder; its material 0 stands for the one current at start */
    bool claimed;              /* taken by the serial pass: written into the scene at v0, n0, t0 */
    size_t v0, n0, t0;
    uint32_t *map;             /* chunk material -> scene material */
    io_builder *keep;          /* where its arrays go when it is freed, for the next window's chunk */
} nff_chunk;

typedef struct nff_par {
    nff_chunk *chunks;
    uint32_t n, next;
    const char *path, *end;
} nff_par;

static bool nff_sync_line(const char *p) {
    if (p[0] == 'f') return p[1] == ' ' || p[1] == '\t';
    if (p[0] != 'p') return false;
    if (p[1] == 'p') return p[2] == ' ' || p[2] == '\t';
    return p[1] == ' ' || p[1] == '\t';
}

/* The first line at or after p (p itself when it starts one) that begins like a chunk. */
static const char *nff_sync(const char *p, const char *begin, const char *end) {
    if (p > begin && p[-1] != '\n') {
        const char *nl = memchr(p, '\n', (size_t)(end - p));
        p = nl ? nl + 1 : end;
    }
    while (p < end && !nff_sync_line(p)) {
        const char *nl = memchr(p, '\n', (size_t)(end - p));
        p = nl ? nl + 1 : end;
    }
    return p;
}

static void nff_chunk_task(void *user, uint32_t index) {
    nff_par *par = user;
    nff_chunk *c = &par->chunks[index];
    io_ctx *ctx = &c->ctx;
    c->stop = c->start;
    c->lines = 0;
    ctx->failed = true; /* writes no message: the serial pass does, at the stop */
    ctx->threads = 1;
    rp_material_data inherited;
    builder_material_defaults(&inherited, "");
    nff_state *st = calloc(1, sizeof *st);
    if (!st || builder_add_material(ctx, &inherited) != 0) {
        free(st);
        return;
    }
    xf_identity(&st->stack[0].xf);
    st->stack[0].anim = -1;
    st->material = 0;
    nff_file f = {.ctx = ctx, .st = st, .path = par->path, .p = c->start, .end = par->end, .line = 0};
    io_builder *b = &ctx->b;
    /* counting lines is a pass over the text: not done again for arrays kept from a window before */
    b->hint = b->pos_cap ? (size_t)(c->limit - c->start) / 16 + 16 : io_text_vertex_hint(c->start, c->limit);
    for (;;) {
        nff_skip(&f);
        const char *cmd = f.p;
        uint32_t line = f.line;
        if (cmd >= c->limit || cmd >= f.end) break;
        size_t pos_n = b->pos_n, nrm_n = b->nrm_n, tri_n = b->tri_n, mat_n = b->material_n;
        size_t n = 0;
        while (!nff_delim(cmd[n])) n++;
        f.p = cmd + n;
        bool ok = false;
        if (n == 1 && cmd[0] == 'p') ok = nff_poly(&f, false);
        else if (n == 2 && cmd[0] == 'p' && cmd[1] == 'p') ok = nff_poly(&f, true);
        else if (n == 1 && cmd[0] == 'f') ok = nff_fill(&f);
        if (!ok) { /* left to the serial pass, as if this chunk ended here */
            b->pos_n = pos_n, b->nrm_n = nrm_n, b->tri_n = tri_n, b->material_n = mat_n;
            f.p = cmd;
            f.line = line;
            break;
        }
    }
    c->stop = f.p;
    c->lines = f.line;
    free(st);
}

static void nff_chunk_free(nff_chunk *c) {
    if (c->keep) { /* the arrays that hold its geometry, kept mapped for the next window */
        io_builder *b = &c->ctx.b, *k = c->keep;
        k->pos = b->pos, k->pos_cap = b->pos_cap, k->nrm = b->nrm, k->nrm_cap = b->nrm_cap;
        k->idx = b->idx, k->nidx = b->nidx, k->mat = b->mat, k->tri_cap = b->tri_cap;
        b->pos = b->nrm = NULL, b->idx = b->nidx = b->mat = NULL;
        b->pos_cap = b->nrm_cap = b->tri_cap = 0;
        c->keep = NULL;
    }
    free(c->map);
    c->map = NULL;
    c->claimed = false;
    builder_free(&c->ctx.b);
    free(c->ctx.scratch_u);
    free(c->ctx.scratch_f);
    memset(&c->ctx, 0, sizeof c->ctx);
}

/* Splits the file into chunks and parses them; leaves par->n at 0 (all serial) for small files.
 * keep (a streamed file's windows: NULL otherwise) holds io_chunk_count builders whose arrays the
 * chunks reuse and give back: a window's chunks then write into memory already mapped. total, when
 * more than size (a streamed file's first window), is the file's size: the scene's arrays are then
 * sized for the whole file from this window's counts, not grown (copied, and faulted in twice)
 * window after window; only address space, pages the file does not fill are never touched. */
static void nff_par_start(io_ctx *ctx, nff_par *par, const char *path, const char *data, size_t size, io_builder *keep,
                          uint64_t total) {
    memset(par, 0, sizeof *par);
    uint32_t k = io_chunk_count(ctx, size);
    if (k < 2 || !(par->chunks = calloc(k, sizeof *par->chunks))) return;
    const char *end = data + size;
    for (uint32_t i = 0; i < k; i++) {
        const char *s = nff_sync(data + (uint64_t)size * i / k, data, end);
        if (s >= end || (par->n && s <= par->chunks[par->n - 1].start)) continue;
        nff_chunk *c = &par->chunks[par->n++];
        c->start = s;
        builder_init(&c->ctx.b);
        if (keep) {
            io_builder *b = &c->ctx.b, *kb = &keep[par->n - 1];
            b->pos = kb->pos, b->pos_cap = kb->pos_cap, b->nrm = kb->nrm, b->nrm_cap = kb->nrm_cap;
            b->idx = kb->idx, b->nidx = kb->nidx, b->mat = kb->mat, b->tri_cap = kb->tri_cap;
            builder_init(kb);
            c->keep = kb;
        }
    }
    for (uint32_t i = 0; i < par->n; i++) par->chunks[i].limit = i + 1 < par->n ? par->chunks[i + 1].start : end;
    par->path = path;
    par->end = end;
    io_parallel_for(ctx->threads, par->n, nff_chunk_task, par);
    /* The scene's arrays sized once for every chunk, not grown (and copied) chunk by chunk. */
    size_t pos = 0, nrm = 0, tri = 0;
    for (uint32_t i = 0; i < par->n; i++) {
        const io_builder *cb = &par->chunks[i].ctx.b;
        pos += cb->pos_n, nrm += cb->nrm_n, tri += cb->tri_n;
    }
    if (total > size) {
        double scale = (double)total / (double)size * 1.03, most = (double)(total / 6 + 16);
        pos = (size_t)fmin((double)pos * scale, most), tri = (size_t)fmin((double)tri * scale, most);
        nrm = (size_t)fmin((double)nrm * scale, most);
    }
    (void)(builder_reserve_vertices(ctx, pos) && builder_reserve_normals(ctx, nrm) && builder_reserve_triangles(ctx, tri));
}

static void nff_par_end(nff_par *par) {
    for (uint32_t i = 0; i < par->n; i++) nff_chunk_free(&par->chunks[i]);
    free(par->chunks);
    memset(par, 0, sizeof *par);
}

/* Takes a chunk's result into the scene as the serial pass would have built it: its materials now,
 * in order, and room for its vertices and triangles, which nff_par_fill writes once the file is
 * read (the serial pass reads no earlier vertex in the meantime). */
static bool nff_chunk_claim(nff_file *f, nff_chunk *c) {
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    const io_builder *cb = &c->ctx.b;
    if (!(c->map = malloc(cb->material_n * sizeof *c->map))) return io_error(ctx, f->shown, f->line, "out of memory");
    /* Triangles of the material current at the start come before the chunk's first `f`. */
    bool inherits = cb->tri_n && cb->mat[0] == 0;
    c->map[0] = inherits ? nff_material(f) : IO_NONE;
    if (inherits && c->map[0] == IO_NONE) return io_error(ctx, f->shown, f->line, "out of memory");
    for (size_t i = 1; i < cb->material_n; i++) {
        rp_material_data m = cb->materials[i];
        if (!nff_add_material(f, &m)) return false;
        c->map[i] = f->st->material;
    }
    bool normals = false;
    for (size_t i = 0; cb->nidx && !normals && i < cb->tri_n; i++) normals = cb->nidx[3 * i] != IO_NONE;
    c->v0 = b->pos_n, c->n0 = b->nrm_n, c->t0 = b->tri_n;
    if (b->pos_n + cb->pos_n >= UINT32_MAX || b->nrm_n + cb->nrm_n >= UINT32_MAX ||
        !builder_reserve_vertices(ctx, cb->pos_n) || !builder_reserve_normals(ctx, cb->nrm_n) ||
        !builder_claim_triangles(ctx, cb->tri_n, normals, false))
        return io_error(ctx, f->shown, f->line, "out of memory");
    b->pos_n += cb->pos_n;
    b->nrm_n += cb->nrm_n;
    c->claimed = true;
    return true;
}

typedef struct nff_fill_job {
    io_builder *b;
    nff_chunk **chunks;
} nff_fill_job;

static void nff_fill_task(void *user, uint32_t index) {
    nff_fill_job *job = user;
    nff_chunk *c = job->chunks[index];
    io_builder *b = job->b;
    const io_builder *cb = &c->ctx.b;
    if (cb->pos_n) memcpy(b->pos + 3 * c->v0, cb->pos, 3 * sizeof(float) * cb->pos_n);
    if (cb->nrm_n) memcpy(b->nrm + 3 * c->n0, cb->nrm, 3 * sizeof(float) * cb->nrm_n);
    uint32_t v0 = (uint32_t)c->v0, n0 = (uint32_t)c->n0;
    for (size_t i = 0; i < cb->tri_n; i++) {
        size_t k = 3 * (c->t0 + i);
        const uint32_t *iv = cb->idx + 3 * i, *in = cb->nidx ? cb->nidx + 3 * i : NULL;
        bool has_n = in && in[0] != IO_NONE;
        for (int j = 0; j < 3; j++) {
            b->idx[k + j] = v0 + iv[j];
            if (b->nidx) b->nidx[k + j] = has_n ? n0 + in[j] : IO_NONE;
            if (b->tidx) b->tidx[k + j] = IO_NONE;
        }
        b->mat[c->t0 + i] = c->map[cb->mat[i]];
    }
    nff_chunk_free(c);
}

/* Writes the claimed chunks into the scene's arrays, in parallel. */
static bool nff_par_fill(io_ctx *ctx, nff_par *par) {
    nff_chunk **list = malloc((par->n + 1) * sizeof *list);
    if (!list) return false;
    uint32_t n = 0;
    for (uint32_t i = 0; i < par->n; i++)
        if (par->chunks[i].claimed) list[n++] = &par->chunks[i];
    nff_fill_job job = {.b = &ctx->b, .chunks = list};
    io_parallel_for(ctx->threads, n, nff_fill_task, &job);
    free(list);
    return true;
}

/* At f->p: takes the chunk that starts there, if one does and its state holds; true when it did
 * (*ok false after an error), f then past the chunk. Chunks the serial pass went past are dropped. */
static bool nff_par_take(nff_file *f, nff_par *par, bool *ok) {
    while (par->next < par->n && par->chunks[par->next].start < f->p) nff_chunk_free(&par->chunks[par->next++]);
    if (par->next >= par->n || par->chunks[par->next].start != f->p) return false;
    nff_chunk *c = &par->chunks[par->next++];
    if (f->st->depth != 0 || c->stop == c->start) {
        nff_chunk_free(c);
        return false;
    }
    *ok = nff_chunk_claim(f, c);
    f->ctx->chunks_taken++;
    f->p = c->stop;
    f->line += c->lines;
    return true;
}

/* ---- streamed files ---------------------------------------------------------------------------- */

static bool nff_command(nff_file *f);

/* What a command may change before it finds that it needs text past its window, so that it can be
 * undone and parsed again on a larger window. Materials, textures and the default material are not
 * in it: a command adds them only after reading all it reads (`f`, `fm`) or finds them again when
 * parsed again (a texture and its material are shared by name). */
typedef struct nff_mark {
    size_t pos_n, nrm_n, uv_n, tri_n, sphere_n, cone_n, light_n;
    size_t anim_n, key_n, akey_n, vis_n, tpa_n, tpak_n;
    int depth, detail;
    rp_camera_data camera;
    float background[3], start, end;
    bool has_background, has_range;
    int32_t frames;
} nff_mark;

static void nff_mark_set(nff_file *f, nff_mark *m) {
    const io_builder *b = &f->ctx->b;
    const nff_state *st = f->st;
    m->pos_n = b->pos_n, m->nrm_n = b->nrm_n, m->uv_n = b->uv_n, m->tri_n = b->tri_n;
    m->sphere_n = b->sphere_n, m->cone_n = b->cone_n, m->light_n = b->light_n;
    m->anim_n = st->anim_n, m->key_n = st->key_n, m->akey_n = st->akey_n, m->vis_n = st->vis_n;
    m->tpa_n = st->tpa_n, m->tpak_n = st->tpak_n;
    m->depth = st->depth, m->detail = st->detail;
    m->camera = b->camera;
    memcpy(m->background, b->background, sizeof m->background);
    m->has_background = b->has_background;
    m->has_range = st->has_range, m->start = st->start, m->end = st->end, m->frames = st->frames;
    f->saved_key_at = SIZE_MAX;
}

static void nff_undo(nff_file *f, const nff_mark *m) {
    io_builder *b = &f->ctx->b;
    nff_state *st = f->st;
    b->pos_n = m->pos_n, b->nrm_n = m->nrm_n, b->uv_n = m->uv_n, b->tri_n = m->tri_n;
    b->sphere_n = m->sphere_n, b->cone_n = m->cone_n, b->light_n = m->light_n;
    st->anim_n = m->anim_n, st->key_n = m->key_n, st->akey_n = m->akey_n, st->vis_n = m->vis_n;
    st->tpa_n = m->tpa_n, st->tpak_n = m->tpak_n;
    st->depth = m->depth, st->detail = m->detail;
    b->camera = m->camera;
    memcpy(b->background, m->background, sizeof m->background);
    b->has_background = m->has_background;
    st->has_range = m->has_range, st->start = m->start, st->end = m->end, st->frames = m->frames;
    if (f->saved_key_at != SIZE_MAX && f->saved_key_at < st->key_n) st->keys[f->saved_key_at] = f->saved_key;
    f->starved = false;
}

/* Where a block of an SPD file ends: before the last `p`, `pp` or `f` line in its last 64 kB, so
 * that a window ends with a whole polygon list (nothing carried over to parse again); else after
 * its last newline. */
static size_t nff_cut(const char *data, size_t size) {
    size_t last = io_cut_lines(data, size);
    if (!last) return 0;
    size_t floor = size > (64u << 10) ? size - (64u << 10) : 0;
    for (size_t i = last; i > floor && i > 0;) {
        if (data[i - 1] == '\n' && i + 3 <= size && nff_sync_line(data + i)) return i;
        i--;
    }
    return last;
}

/* Grows the window to hold [p, end) and the next block: copies both into *own (the tail may lie in
 * it already) and gives the blocks back. */
static bool nff_window_append(char **own, size_t *own_cap, const char *p, size_t tail, const io_text *next) {
    size_t need = tail + next->size + 1;
    size_t off = *own && p >= *own && p < *own + *own_cap ? (size_t)(p - *own) : SIZE_MAX;
    if (need > *own_cap) {
        size_t c = *own_cap ? *own_cap : need;
        while (c < need) c = c <= SIZE_MAX / 4 ? 2 * c : need;
        char *d = io_realloc(*own, c);
        if (!d) return false;
        if (off != SIZE_MAX) p = d + off;
        *own = d;
        *own_cap = c;
    }
    memmove(*own, p, tail);
    memcpy(*own + tail, next->data, next->size);
    (*own)[tail + next->size] = '\0';
    return true;
}

/* nff_parse for a gzip'd file on disk read as a stream (io_stream): the same commands, errors and
 * line numbers, window by window. A window is a block of the stream where it can be (no copy), or
 * a command that went past the end of one block (a polygon list over a block boundary, a line
 * longer than a block) with the following block. Each window's polygon lists are parsed in
 * parallel chunks as a whole file's are, while the stream's thread inflates the next blocks. */
static bool nff_parse_stream(io_ctx *ctx, nff_state *st, const char *path, io_stream *s) {
    nff_file f = {.ctx = ctx, .st = st, .path = path, .line = 1, .saved_key_at = SIZE_MAX};
    vfs_display(&ctx->vfs, path, f.shown, sizeof f.shown);
    char *own = NULL; /* the window when it is not a block */
    size_t own_cap = 0;
    int held = 0; /* blocks not given back yet */
    bool ok = true, stream_bad = false;
    io_text t;
    if (!io_stream_next(s, ctx, &t)) {
        io_stream_close(s);
        return io_error(ctx, f.shown, 0, "cannot open: %s", ctx->why);
    }
    held = 1;
    f.p = t.data, f.end = t.data + t.size, f.more = !t.last;
    size_t starved_at = 0; /* window size at the last starvation: the next window is at least twice it */
    io_builder *keep = NULL; /* the chunks' arrays, from window to window */
    uint32_t keep_n = 0;
    for (;;) {
        ctx->blocks++;
        nff_par par;
        uint32_t k = io_chunk_count(ctx, (size_t)(f.end - f.p));
        if (k > keep_n) {
            io_builder *g = io_realloc(keep, k * sizeof *keep);
            if (!g) {
                ok = io_error(ctx, f.shown, f.line, "out of memory");
                break;
            }
            keep = g;
            for (uint32_t i = keep_n; i < k; i++) builder_init(&keep[i]);
            keep_n = k;
        }
        nff_par_start(ctx, &par, path, f.p, (size_t)(f.end - f.p), keep,
                      ctx->blocks == 1 && f.more ? io_stream_size_hint(s) : 0);
        starved_at = 0;
        for (;;) {
            nff_skip(&f);
            if (f.p >= f.end) break;
            if (par.n && nff_par_take(&f, &par, &ok)) {
                if (!ok) break;
                continue;
            }
            if (*f.p == '\0' || *f.p == '{') {
                ok = io_error(ctx, f.shown, f.line, "%s", *f.p ? "unexpected '{'" : "binary data (NUL byte) in a text file");
                break;
            }
            const char *cmd = f.p;
            uint32_t line = f.line;
            nff_mark m;
            nff_mark_set(&f, &m);
            if (!(ok = nff_command(&f))) {
                if (f.starved) {
                    nff_undo(&f, &m);
                    f.p = cmd, f.line = line;
                    starved_at = (size_t)(f.end - f.p);
                    ok = true;
                }
                break;
            }
        }
        if (ok && par.n && !nff_par_fill(ctx, &par)) ok = io_error(ctx, f.shown, f.line, "out of memory");
        nff_par_end(&par);
        if (!ok || !f.more) break;
        /* the next window: the command left over (if any) and one block, or more blocks when it
         * starved (so a command much longer than a block is not parsed again block after block) */
        size_t tail = f.p < f.end ? (size_t)(f.end - f.p) : 0;
        const char *p = f.p;
        do {
            if (!io_stream_next(s, ctx, &t)) {
                stream_bad = true;
                break;
            }
            held++;
            if (tail == 0) { /* the block itself */
                while (held > 1) io_stream_release(s), held--;
                f.p = t.data, f.end = t.data + t.size;
            } else {
                if (!nff_window_append(&own, &own_cap, p, tail, &t)) {
                    ok = io_error(ctx, f.shown, f.line, "out of memory");
                    break;
                }
                while (held > 0) io_stream_release(s), held--;
                tail += t.size;
                p = own;
                f.p = own, f.end = own + tail;
            }
            f.more = !t.last;
        } while (f.more && starved_at && (size_t)(f.end - f.p) < 2 * starved_at);
        if (!ok || stream_bad) break;
    }
    if (ok && !stream_bad && st->depth > 0) {
        const nff_level *lv = &st->stack[st->depth];
        ok = io_error(ctx, f.shown, f.line, "end of file inside the transform block opened at line %u", lv->line);
    }
    while (held > 0) io_stream_release(s), held--;
    /* a parse error in a file that turns out corrupt or too large is reported as the whole-buffer
     * read reports it: the file first */
    if (!stream_bad && !ok) stream_bad = !io_stream_drain(s, ctx);
    if (stream_bad) {
        ctx->failed = false;
        ok = io_error(ctx, f.shown, 0, "cannot open: %s", ctx->why);
    }
    ctx->bytes += io_stream_total(s);
    io_stream_close(s);
    free(own);
    for (uint32_t i = 0; i < keep_n; i++) builder_free(&keep[i]);
    free(keep);
    return ok;
}

/* ---- files ------------------------------------------------------------------------------------ */

static bool nff_parse(io_ctx *ctx, nff_state *st, const char *path, const nff_file *from, const char *as_written);

static bool nff_include(nff_file *f) {
    int64_t level;
    char name[IO_PATH_MAX], full[IO_PATH_MAX];
    if (!nff_int(f, &level, "include detail level") || !nff_word(f, name, sizeof name, "include file name")) return false;
    if (level > f->st->detail) return true; /* more detail than asked for */
    io_ctx *ctx = f->ctx;
    if (ctx->depth >= NFF_MAX_INCLUDE) return io_error(ctx, f->shown, f->line, "includes nested too deep (a cycle?)");
    /* The total is capped as well as the depth: a file that includes the next one twice, 32 deep,
     * would otherwise parse 2^32 files. */
    if (ctx->includes >= ctx->limits.max_includes)
        return io_error(ctx, f->shown, f->line,
                        "more than %llu included files (an include bomb?); RP_MAX_INCLUDES raises the limit",
                        (unsigned long long)ctx->limits.max_includes);
    ctx->includes++;
    vfs_join(&ctx->vfs, f->path, name, full, sizeof full);
    ctx->depth++;
    bool ok = nff_parse(ctx, f->st, full, f, name);
    ctx->depth--;
    return ok;
}

static bool nff_command(nff_file *f) {
    const char *p = f->p;
    size_t n = 0;
    while (!nff_delim(p[n])) n++;
    f->p += n;
    char c0 = p[0], c1 = n > 1 ? p[1] : '\0';
    switch (n) {
    case 1:
        switch (c0) {
        case 'p': return nff_poly(f, false);
        case 's': return nff_sphere(f);
        case 'c': return nff_cone(f);
        case 'l': return nff_light(f, false);
        case 'f': return nff_fill(f);
        case 'b': {
            io_builder *b = &f->ctx->b;
            b->has_background = true;
            return nff_floats(f, b->background, 3, "b") && nff_nonnegative(f, b->background, 0, 3, "b");
        }
        case 'v': return nff_viewpoint(f);
        case 'm': return nff_mesh(f);
        case 'i': return nff_include(f);
        case 'x': return nff_transform(f, false);
        case 'k': return nff_keyframes(f);
        case '}': return nff_close(f);
        case 'a': { /* animation start, end, frame count */
            nff_state *st = f->st;
            int64_t frames;
            if (!nff_float(f, &st->start, "a start") || !nff_float(f, &st->end, "a end") || !nff_int(f, &frames, "a frames"))
                return false;
            if (frames < 1 || frames > 10000000)
                return io_error(f->ctx, f->shown, f->line, "a: %lld frames (1 to 10^7)", (long long)frames);
            if (!(st->end >= st->start) || (frames > 1 && !(st->end > st->start)))
                return io_error(f->ctx, f->shown, f->line, "a: the animation ends (%g) before it starts (%g)", (double)st->end,
                                (double)st->start);
            st->frames = (int32_t)frames;
            st->has_range = true;
            return true;
        }
        case 'd': {
            int64_t d;
            if (!nff_int(f, &d, "d")) return false;
            f->st->detail = (int)(d < 0 ? 0 : d > 1000 ? 1000 : d);
            return true;
        }
        default: break;
        }
        break;
    case 2:
        if (c0 == 'p' && c1 == 'p') return nff_poly(f, true);
        if (c0 == 'f' && c1 == 'm') return nff_fill_material(f);
        if (c0 == 'x' && c1 == 's') return nff_transform(f, true);
        if (c0 == 't' && c1 == 't') return nff_textured_triangle(f, false);
        if (c0 == 'l' && c1 == 'a') return nff_light(f, true);
        if (c0 == 'a' && c1 == 'm') return nff_floats(f, f->st->ambient, 3, "am");
        break;
    case 3:
        if (memcmp(p, "ttp", 3) == 0) return nff_textured_triangle(f, true);
        if (memcmp(p, "tpa", 3) == 0) return nff_animated_triangle(f);
        break;
    default: break;
    }
    char tok[32];
    f->p = p;
    return io_error(f->ctx, f->shown, f->line, "unknown command '%s'", nff_preview(f, p, tok, sizeof tok));
}

/* Parses one file; `from` is the file whose `i` line includes it (NULL for the scene itself), where
 * errors about reading it are reported. */
static bool nff_parse(io_ctx *ctx, nff_state *st, const char *path, const nff_file *from, const char *as_written) {
    /* a large gzip'd scene on disk is streamed; includes and archive entries are read whole */
    if (!from && !ctx->vfs.archive && ctx->stream >= 0 && (ctx->stream > 0 || ctx->threads > 1)) {
        io_stream *s = io_stream_open(ctx, path, ctx->stream > 0 ? 0 : IO_STREAM_MIN_TEXT, ctx->stream_block, nff_cut);
        if (s) return nff_parse_stream(ctx, st, path, s);
    }
    nff_file f = {.ctx = ctx, .st = st, .path = path, .line = 1, .saved_key_at = SIZE_MAX};
    vfs_display(&ctx->vfs, path, f.shown, sizeof f.shown);
    io_buf buf;
    if (!vfs_read(ctx, path, &buf)) {
        if (from)
            return io_error(ctx, from->shown, from->line, "cannot open include '%s' (%s): %s", as_written, f.shown,
                            ctx->why);
        return io_error(ctx, f.shown, 0, "cannot open: %s", ctx->why);
    }
    ctx->bytes += buf.size;
    if (from) {
        ctx->include_bytes += buf.size;
        if (ctx->include_bytes > ctx->limits.max_include_bytes) {
            vfs_buf_free(&buf);
            return io_error(ctx, from->shown, from->line,
                            "included files exceed %llu bytes in all (an include bomb?); RP_MAX_INCLUDE_BYTES "
                            "raises the limit",
                            (unsigned long long)ctx->limits.max_include_bytes);
        }
    }
    f.p = buf.data;
    f.end = buf.data + buf.size;
    int depth0 = st->depth;
    bool ok = true;
    nff_par par;
    nff_par_start(ctx, &par, path, buf.data, buf.size, NULL, 0);
    for (;;) {
        nff_skip(&f);
        if (f.p >= f.end) break;
        if (par.n && nff_par_take(&f, &par, &ok)) {
            if (!ok) break;
            continue;
        }
        if (*f.p == '\0' || *f.p == '{') {
            ok = io_error(ctx, f.shown, f.line, "%s", *f.p ? "unexpected '{'" : "binary data (NUL byte) in a text file");
            break;
        }
        if (!(ok = nff_command(&f))) break;
    }
    if (ok && st->depth > depth0) {
        const nff_level *lv = &st->stack[st->depth];
        ok = io_error(ctx, f.shown, f.line, "end of file inside the transform block opened at line %u", lv->line);
    }
    if (ok && st->depth < depth0) ok = io_error(ctx, f.shown, f.line, "file closes a transform block it did not open");
    if (ok && par.n && !nff_par_fill(ctx, &par)) ok = io_error(ctx, f.shown, f.line, "out of memory");
    nff_par_end(&par);
    vfs_buf_free(&buf);
    return ok;
}

/* BART's shading adds `am` x the material's ambient colour (x its texture) to every surface. A
 * surface that has nothing else (no diffuse, specular or transmission: the kitchen's garden seen
 * through the windows) is a picture that lights itself, so it becomes an emitter of that radiance,
 * textured as the surface is. The ambient term of the other surfaces is not carried over (DESIGN.md:
 * no ambient term in a physically based image; Whitted keeps its own). */
static void nff_ambient_emitters(io_ctx *ctx, const nff_state *st) {
    for (size_t i = 0; i < ctx->b.material_n; i++) {
        rp_material_data *m = &ctx->b.materials[i];
        bool other = false, ambient = false;
        for (int c = 0; c < 3; c++) {
            other |= m->kd[c] > 0.0f || m->ks[c] > 0.0f || m->kr[c] > 0.0f || m->kt[c] > 0.0f || m->ke[c] > 0.0f;
            ambient |= m->ka[c] * st->ambient[c] > 0.0f;
        }
        if (other || !ambient || m->illum >= 0) continue;
        for (int c = 0; c < 3; c++) m->ke[c] = fmaxf(m->ka[c] * st->ambient[c], 0.0f);
        if (m->map_kd >= 0) m->map_ke = m->map_kd + 1;
    }
}

bool nff_load(io_ctx *ctx, const char *path) {
    nff_state *st = io_calloc(1, sizeof *st);
    if (!st) {
        char shown[IO_PATH_MAX + 256];
        vfs_display(&ctx->vfs, path, shown, sizeof shown);
        return io_error(ctx, shown, 0, "out of memory");
    }
    st->material = IO_NONE;
    xf_identity(&st->stack[0].xf);
    st->stack[0].anim = -1;
    bool ok = nff_parse(ctx, st, path, NULL, path);
    if (ok) nff_ambient_emitters(ctx, st);
    if (ok) {
        char shown[IO_PATH_MAX + 256];
        vfs_display(&ctx->vfs, path, shown, sizeof shown);
        ok = nff_animation(ctx, st, shown);
    }
    free(st->anims);
    free(st->keys);
    free(st->tex_mats);
    free(st->akeys);
    free(st->vis_t);
    free(st->vis_v);
    free(st->tpas);
    free(st->tpa_keys);
    free(st);
    return ok;
}
