/* PLY (ASCII, binary little and big endian). The header declares elements and their properties;
 * the vertex element gives positions (and normals, texture coordinates when present), the face
 * element a vertex index list per face (a `tristrips` element a triangle strip per list). Every
 * other element and property, lists included, is read past by its declared type. */
#include <math.h>
#include <stdio.h>

#include "io/io_internal.h"

typedef enum ply_type {
    PLY_NONE = 0,
    PLY_I8,
    PLY_U8,
    PLY_I16,
    PLY_U16,
    PLY_I32,
    PLY_U32,
    PLY_F32,
    PLY_F64
} ply_type;

typedef enum ply_format { PLY_ASCII, PLY_BINARY_LE, PLY_BINARY_BE } ply_format;

/* What a vertex property feeds: nothing, or one coordinate, or one colour channel. */
enum {
    PLY_USE_NONE = 0,
    PLY_USE_X,
    PLY_USE_Y,
    PLY_USE_Z,
    PLY_USE_NX,
    PLY_USE_NY,
    PLY_USE_NZ,
    PLY_USE_U,
    PLY_USE_V,
    PLY_USE_R,
    PLY_USE_G,
    PLY_USE_B
};

typedef struct ply_prop {
    ply_type type;
    ply_type count_type; /* PLY_NONE: not a list */
    int use;
} ply_prop;

typedef struct ply_elem {
    char name[64];
    uint64_t count;
    uint32_t line; /* header line declaring it */
    ply_prop *props;
    size_t prop_n, prop_cap;
    int face_list; /* index of the vertex index list in a face element, -1 if none */
    int face_uv;   /* index of a face's per-corner texture coordinates (MeshLab's texcoord list), -1 if none */
} ply_elem;

typedef struct ply_file {
    io_ctx *ctx;
    char shown[IO_PATH_MAX + 256];
    ply_format format;
    ply_elem *elems;
    size_t elem_n, elem_cap;
    const char *p, *end;
    uint32_t line;
    uint64_t vertex_count;
    size_t vertex_base, nrm_base, uv_base; /* where the vertex element's first position, normal, uv went */
    bool has_normals, has_uv, has_color;
    char texture[256]; /* MeshLab's `comment TextureFile NAME`, "" when none */
    uint32_t texture_line;
    uint32_t material; /* the faces': textured when the texture loaded, else the default */
    float *wedge;      /* a face's corner texture coordinates (scratch) */
    size_t wedge_cap;
} ply_file;

static size_t ply_size(ply_type t) {
    switch (t) {
    case PLY_I8:
    case PLY_U8: return 1;
    case PLY_I16:
    case PLY_U16: return 2;
    case PLY_I32:
    case PLY_U32:
    case PLY_F32: return 4;
    case PLY_F64: return 8;
    case PLY_NONE: break;
    }
    return 0;
}

static ply_type ply_type_named(const char *s) {
    static const struct {
        const char *name;
        ply_type type;
    } names[] = {{"char", PLY_I8},    {"int8", PLY_I8},     {"uchar", PLY_U8},   {"uint8", PLY_U8},
                 {"short", PLY_I16},  {"int16", PLY_I16},   {"ushort", PLY_U16}, {"uint16", PLY_U16},
                 {"int", PLY_I32},    {"int32", PLY_I32},   {"uint", PLY_U32},   {"uint32", PLY_U32},
                 {"float", PLY_F32},  {"float32", PLY_F32}, {"double", PLY_F64}, {"float64", PLY_F64}};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (strcmp(s, names[i].name) == 0) return names[i].type;
    return PLY_NONE;
}

static int ply_use_named(const char *s) {
    static const struct {
        const char *name;
        int use;
    } names[] = {{"x", PLY_USE_X},         {"y", PLY_USE_Y},         {"z", PLY_USE_Z},
                 {"nx", PLY_USE_NX},       {"ny", PLY_USE_NY},       {"nz", PLY_USE_NZ},
                 {"u", PLY_USE_U},         {"v", PLY_USE_V},         {"s", PLY_USE_U},
                 {"t", PLY_USE_V},         {"texture_u", PLY_USE_U}, {"texture_v", PLY_USE_V},
                 {"texture_s", PLY_USE_U}, {"texture_t", PLY_USE_V}, {"red", PLY_USE_R},
                 {"green", PLY_USE_G},     {"blue", PLY_USE_B},      {"r", PLY_USE_R},
                 {"g", PLY_USE_G},         {"b", PLY_USE_B},         {"diffuse_red", PLY_USE_R},
                 {"diffuse_green", PLY_USE_G}, {"diffuse_blue", PLY_USE_B}};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (strcmp(s, names[i].name) == 0) return names[i].use;
    return PLY_USE_NONE;
}

/* ---- header ----------------------------------------------------------------------------------- */

/* Splits the next header line into at most 6 words. */
static int ply_header_words(ply_file *f, char words[6][64]) {
    int n = 0;
    while (f->p < f->end && *f->p != '\n') {
        while (f->p < f->end && io_is_space(*f->p)) f->p++;
        if (f->p >= f->end || *f->p == '\n') break;
        const char *s = f->p;
        while (f->p < f->end && !io_is_space(*f->p) && *f->p != '\n') f->p++;
        if (n < 6) snprintf(words[n++], 64, "%.*s", (int)(f->p - s), s);
    }
    if (f->p < f->end) f->p++; /* the '\n' */
    return n;
}

static bool ply_read_header(ply_file *f) {
    io_ctx *ctx = f->ctx;
    char w[6][64];
    if (f->end - f->p < 4 || strncmp(f->p, "ply", 3) != 0 || !(f->p[3] == '\n' || f->p[3] == '\r'))
        return io_error(ctx, f->shown, 1, "not a PLY file (no 'ply' magic line)");
    ply_header_words(f, w);
    bool have_format = false;
    for (f->line = 2;; f->line++) {
        if (f->p >= f->end) return io_error(ctx, f->shown, f->line, "header ends without end_header");
        const char *line_start = f->p;
        int n = ply_header_words(f, w);
        if (n == 0) continue;
        if (strcmp(w[0], "end_header") == 0) break;
        if (n >= 3 && strcmp(w[0], "comment") == 0 && strcmp(w[1], "TextureFile") == 0 && !f->texture[0]) {
            /* MeshLab's texture for the texture coordinates: the rest of the line (blanks allowed).
             * The word is looked for in the line's bytes, not by strstr: a NUL in the line (not a
             * blank, so the words above go past it) ended strstr's search before it (UBSan: NULL + 11) */
            const char *a = line_start, *e = f->p;
            while (a + 11 < e && memcmp(a, "TextureFile", 11) != 0) a++;
            a = a + 11 <= e ? a + 11 : e;
            while (a < e && io_is_space(*a)) a++;
            while (e > a && (io_is_space(e[-1]) || e[-1] == '\n')) e--;
            snprintf(f->texture, sizeof f->texture, "%.*s", (int)(e - a), a);
            f->texture_line = f->line;
            continue;
        }
        if (strcmp(w[0], "comment") == 0 || strcmp(w[0], "obj_info") == 0) continue;
        if (strcmp(w[0], "format") == 0) {
            if (n < 2) return io_error(ctx, f->shown, f->line, "format line without a format");
            if (strcmp(w[1], "ascii") == 0) f->format = PLY_ASCII;
            else if (strcmp(w[1], "binary_little_endian") == 0) f->format = PLY_BINARY_LE;
            else if (strcmp(w[1], "binary_big_endian") == 0) f->format = PLY_BINARY_BE;
            else return io_error(ctx, f->shown, f->line, "unknown PLY format '%s'", w[1]);
            have_format = true;
        } else if (strcmp(w[0], "element") == 0) {
            int64_t count;
            const char *e;
            if (n != 3 || !(e = io_parse_int(w[2], &count)) || *e || count < 0)
                return io_error(ctx, f->shown, f->line, "bad element line (expected 'element <name> <count>')");
            if (!io_reserve((void **)&f->elems, &f->elem_cap, f->elem_n + 1, sizeof(ply_elem)))
                return io_error(ctx, f->shown, f->line, "out of memory");
            ply_elem *el = &f->elems[f->elem_n++];
            memset(el, 0, sizeof *el);
            snprintf(el->name, sizeof el->name, "%s", w[1]);
            el->count = (uint64_t)count;
            el->line = f->line;
            el->face_list = -1;
            el->face_uv = -1;
        } else if (strcmp(w[0], "property") == 0) {
            if (f->elem_n == 0) return io_error(ctx, f->shown, f->line, "property before any element");
            ply_elem *el = &f->elems[f->elem_n - 1];
            ply_prop pr = {PLY_NONE, PLY_NONE, PLY_USE_NONE};
            const char *name;
            if (n >= 2 && strcmp(w[1], "list") == 0) {
                if (n != 5) return io_error(ctx, f->shown, f->line, "bad list property line");
                pr.count_type = ply_type_named(w[2]);
                pr.type = ply_type_named(w[3]);
                if (pr.count_type == PLY_NONE || pr.type == PLY_NONE ||
                    pr.count_type == PLY_F32 || pr.count_type == PLY_F64)
                    return io_error(ctx, f->shown, f->line, "bad list property types '%s %s'", w[2], w[3]);
                name = w[4];
            } else {
                if (n != 3) return io_error(ctx, f->shown, f->line, "bad property line");
                pr.type = ply_type_named(w[1]);
                if (pr.type == PLY_NONE) return io_error(ctx, f->shown, f->line, "unknown property type '%s'", w[1]);
                name = w[2];
            }
            if (strcmp(el->name, "vertex") == 0 && pr.count_type == PLY_NONE) pr.use = ply_use_named(name);
            if ((strcmp(el->name, "face") == 0 || strcmp(el->name, "tristrips") == 0) && pr.count_type != PLY_NONE &&
                el->face_list < 0 &&
                (strcmp(name, "vertex_indices") == 0 || strcmp(name, "vertex_index") == 0))
                el->face_list = (int)el->prop_n;
            if (strcmp(el->name, "face") == 0 && pr.count_type != PLY_NONE && el->face_uv < 0 &&
                (pr.type == PLY_F32 || pr.type == PLY_F64) && strcmp(name, "texcoord") == 0)
                el->face_uv = (int)el->prop_n;
            if (!io_reserve((void **)&el->props, &el->prop_cap, el->prop_n + 1, sizeof(ply_prop)))
                return io_error(ctx, f->shown, f->line, "out of memory");
            el->props[el->prop_n++] = pr;
        } else {
            return io_error(ctx, f->shown, f->line, "unknown header line '%s'", w[0]);
        }
    }
    if (!have_format) return io_error(ctx, f->shown, f->line, "no format line in the header");
    f->line++;
    return true;
}

/* ---- values ----------------------------------------------------------------------------------- */

/* The ASCII value of type t at p as a double (integers exactly); returns its end, or NULL when it
 * is not one or is not followed by a blank, a newline or the text's end. */
static const char *ply_ascii_token(const char *p, ply_type t, double *out) {
    const char *q;
    if (t == PLY_F32 || t == PLY_F64) {
        float v = 0.0f;
        q = io_parse_float(p, &v);
        *out = v;
    } else {
        int64_t v = 0;
        q = io_parse_int(p, &v);
        *out = (double)v;
    }
    return q && (io_is_space(*q) || *q == '\n' || *q == '\0') ? q : NULL;
}

/* Next ASCII value as a double (integers exactly), NULL-free: false with the error written. */
static bool ply_ascii_value(ply_file *f, ply_type t, double *out) {
    const char *p = f->p;
    for (;;) {
        while (io_is_space(*p)) p++;
        if (*p == '\n') {
            f->line++;
            p++;
            continue;
        }
        break;
    }
    if (p >= f->end) {
        f->p = p;
        return io_error(f->ctx, f->shown, f->line, "unexpected end of file (truncated data?)");
    }
    const char *q = ply_ascii_token(p, t, out);
    if (!q) {
        int len = 0;
        while (len < 24 && p[len] && !io_is_space(p[len]) && p[len] != '\n') len++;
        return io_error(f->ctx, f->shown, f->line, "expected %s, got '%.*s'",
                        t == PLY_F32 || t == PLY_F64 ? "a finite number" : "an integer", len, p);
    }
    f->p = q;
    return true;
}

static bool ply_binary_value(ply_file *f, ply_type t, double *out) {
    size_t n = ply_size(t);
    if ((size_t)(f->end - f->p) < n)
        return io_error(f->ctx, f->shown, f->line, "unexpected end of binary data at byte %zu (truncated file?)",
                        (size_t)(f->end - f->p));
    uint8_t b[8];
    memcpy(b, f->p, n);
    f->p += n;
    if (f->format == PLY_BINARY_BE)
        for (size_t i = 0; i < n / 2; i++) {
            uint8_t tmp = b[i];
            b[i] = b[n - 1 - i];
            b[n - 1 - i] = tmp;
        }
    switch (t) {
    case PLY_I8: *out = (int8_t)b[0]; break;
    case PLY_U8: *out = b[0]; break;
    case PLY_I16: {
        int16_t v;
        memcpy(&v, b, 2);
        *out = v;
    } break;
    case PLY_U16: {
        uint16_t v;
        memcpy(&v, b, 2);
        *out = v;
    } break;
    case PLY_I32: {
        int32_t v;
        memcpy(&v, b, 4);
        *out = v;
    } break;
    case PLY_U32: {
        uint32_t v;
        memcpy(&v, b, 4);
        *out = v;
    } break;
    case PLY_F32: {
        float v = 0.0f;
        memcpy(&v, b, 4);
        *out = v;
    } break;
    case PLY_F64: memcpy(out, b, 8); break;
    case PLY_NONE: *out = 0; break;
    }
    return true;
}

static bool ply_value(ply_file *f, ply_type t, double *out) {
    return f->format == PLY_ASCII ? ply_ascii_value(f, t, out) : ply_binary_value(f, t, out);
}

/* Moves an ASCII reader to the next value so f->line is the line that value is on. */
static void ply_sync_line(ply_file *f) {
    if (f->format != PLY_ASCII) return;
    while (io_is_space(*f->p) || *f->p == '\n') {
        if (*f->p == '\n') f->line++;
        f->p++;
    }
}

/* ---- elements --------------------------------------------------------------------------------- */

static bool ply_read_list_count(ply_file *f, const ply_prop *pr, uint64_t *count) {
    double c = 0.0;
    if (!ply_value(f, pr->count_type, &c)) return false;
    if (c < 0) return io_error(f->ctx, f->shown, f->line, "negative list size %.0f", c);
    /* Every entry takes its size in bytes (binary) or two (ASCII): a larger count is a lie. */
    double per = f->format == PLY_ASCII ? 2.0 : (double)ply_size(pr->type);
    if (c * per > (double)(f->end - f->p)) return io_error(f->ctx, f->shown, f->line, "list size %.0f exceeds the file", c);
    *count = (uint64_t)c;
    return true;
}

static bool ply_skip_list(ply_file *f, const ply_prop *pr) {
    uint64_t count = 0;
    if (!ply_read_list_count(f, pr, &count)) return false;
    if (f->format != PLY_ASCII) {
        size_t bytes = (size_t)count * ply_size(pr->type);
        if ((size_t)(f->end - f->p) < bytes)
            return io_error(f->ctx, f->shown, f->line, "unexpected end of binary data (truncated file?)");
        f->p += bytes;
        return true;
    }
    double v;
    for (uint64_t i = 0; i < count; i++)
        if (!ply_value(f, pr->type, &v)) return false;
    return true;
}

/* Sets has_normals, has_uv and has_color from the vertex element's properties; false without x, y
 * and z. */
static bool ply_vertex_uses(ply_file *f, const ply_elem *el) {
    bool has_xyz[3] = {false, false, false};
    for (size_t i = 0; i < el->prop_n; i++) {
        int u = el->props[i].use;
        if (u >= PLY_USE_X && u <= PLY_USE_Z) has_xyz[u - PLY_USE_X] = true;
        if (u >= PLY_USE_NX && u <= PLY_USE_NZ) f->has_normals = true;
        if (u == PLY_USE_U || u == PLY_USE_V) f->has_uv = true;
        if (u >= PLY_USE_R && u <= PLY_USE_B) f->has_color = true;
    }
    return has_xyz[0] && has_xyz[1] && has_xyz[2];
}

/* Room for the element's vertices, but no more than the data could hold, so a lying count fails
 * on the data, not on malloc. */
static bool ply_reserve_vertices(ply_file *f, const ply_elem *el) {
    io_ctx *ctx = f->ctx;
    size_t plausible = (size_t)(f->end - f->p) / 2 + 1;
    size_t n = el->count < plausible ? (size_t)el->count : plausible;
    return builder_reserve_vertices(ctx, n) && (!f->has_normals || builder_reserve_normals(ctx, n)) &&
           (!f->has_uv || builder_reserve_texcoords(ctx, n));
}

/* A vertex's values, by what each property feeds. */
typedef struct ply_vertex {
    float xyz[3], nrm[3], uv[2], rgb[3];
} ply_vertex;

static const ply_vertex ply_vertex_zero = {{0, 0, 0}, {0, 0, 0}, {0, 0}, {1, 1, 1}};

/* A colour channel as written: an integer type's range maps to [0, 1] (uchar 255, ushort 65535),
 * floats are taken as they are; then sRGB-decoded (colours in files are display colours). */
static float ply_color(ply_type t, double v) {
    double full = t == PLY_U8 || t == PLY_I8 ? 255.0 : t == PLY_U16 || t == PLY_I16 ? 65535.0 : 1.0;
    return io_srgb_to_linear((float)(v / full));
}

/* Stores one property's value by what it feeds (nothing, one coordinate or one colour channel). */
static void ply_vertex_value(const ply_prop *pr, double v, ply_vertex *out) {
    float *xyz = out->xyz, *nrm = out->nrm, *uv = out->uv;
    switch (pr->use) {
    case PLY_USE_X: xyz[0] = (float)v; break;
    case PLY_USE_Y: xyz[1] = (float)v; break;
    case PLY_USE_Z: xyz[2] = (float)v; break;
    case PLY_USE_NX: nrm[0] = (float)v; break;
    case PLY_USE_NY: nrm[1] = (float)v; break;
    case PLY_USE_NZ: nrm[2] = (float)v; break;
    case PLY_USE_U: uv[0] = (float)v; break;
    case PLY_USE_V: uv[1] = (float)v; break;
    case PLY_USE_R: out->rgb[0] = ply_color(pr->type, v); break;
    case PLY_USE_G: out->rgb[1] = ply_color(pr->type, v); break;
    case PLY_USE_B: out->rgb[2] = ply_color(pr->type, v); break;
    default: break;
    }
}

/* (Colours are finite: ply_color maps NaN to 0.) */
static bool ply_vertex_finite(const ply_vertex *w) {
    return isfinite(w->xyz[0]) && isfinite(w->xyz[1]) && isfinite(w->xyz[2]) && isfinite(w->nrm[0]) &&
           isfinite(w->nrm[1]) && isfinite(w->nrm[2]) && isfinite(w->uv[0]) && isfinite(w->uv[1]);
}

static bool ply_read_vertices(ply_file *f, const ply_elem *el) {
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    if (el->count > UINT32_MAX - b->pos_n) return io_error(ctx, f->shown, el->line, "too many vertices");
    if (!ply_vertex_uses(f, el)) return io_error(ctx, f->shown, el->line, "vertex element without x, y and z properties");
    if (!ply_reserve_vertices(f, el)) return io_error(ctx, f->shown, el->line, "out of memory");
    f->vertex_base = b->pos_n;
    for (uint64_t k = 0; k < el->count; k++) {
        if (b->pos_n >= b->pos_cap && !builder_reserve_vertices(ctx, 1)) return io_error(ctx, f->shown, f->line, "out of memory");
        if (f->has_normals && b->nrm_n >= b->nrm_cap && !builder_reserve_normals(ctx, 1))
            return io_error(ctx, f->shown, f->line, "out of memory");
        if (f->has_uv && b->uv_n >= b->uv_cap && !builder_reserve_texcoords(ctx, 1))
            return io_error(ctx, f->shown, f->line, "out of memory");
        ply_vertex w = ply_vertex_zero;
        ply_sync_line(f);
        uint32_t line = f->line;
        for (size_t i = 0; i < el->prop_n; i++) {
            const ply_prop *pr = &el->props[i];
            if (pr->count_type != PLY_NONE) {
                if (!ply_skip_list(f, pr)) return false;
                continue;
            }
            double v;
            if (!ply_value(f, pr->type, &v)) return false;
            ply_vertex_value(pr, v, &w);
        }
        if (!ply_vertex_finite(&w))
            return io_error(ctx, f->shown, line, "vertex %llu has a NaN or infinite value", (unsigned long long)k);
        if (f->has_color && !builder_set_colors(ctx, b->pos_n, w.rgb, 1))
            return io_error(ctx, f->shown, f->line, "out of memory");
        memcpy(b->pos + 3 * b->pos_n++, w.xyz, sizeof w.xyz);
        if (f->has_normals) memcpy(b->nrm + 3 * b->nrm_n++, w.nrm, sizeof w.nrm);
        if (f->has_uv) memcpy(b->uv + 2 * b->uv_n++, w.uv, sizeof w.uv);
    }
    f->vertex_count = el->count;
    f->nrm_base = b->nrm_n - (f->has_normals ? (size_t)el->count : 0);
    f->uv_base = b->uv_n - (f->has_uv ? (size_t)el->count : 0);
    return true;
}

/* The triangles of a face of n corners s[] (indices into pos): 3(n-2) corner numbers into tris;
 * ring holds n, pts (unused for a triangle) 3n floats. */
static void ply_triangulate(const float *pos, const uint32_t *s, uint32_t n, uint32_t *tris, uint32_t *ring, float *pts) {
    if (n == 3) {
        tris[0] = 0, tris[1] = 1, tris[2] = 2;
        return;
    }
    for (uint32_t j = 0; j < n; j++) memcpy(pts + 3 * j, pos + 3 * (size_t)s[j], 3 * sizeof(float));
    poly_triangulate(pts, n, tris, ring);
}

/* PLY normals and coordinates are per vertex: a corner's indices are its vertex's. */
static void ply_corner_indices(const ply_file *f, const uint32_t v[3], uint32_t nn[3], uint32_t tt[3]) {
    for (int j = 0; j < 3; j++) {
        nn[j] = (uint32_t)(v[j] - f->vertex_base + f->nrm_base);
        tt[j] = (uint32_t)(v[j] - f->vertex_base + f->uv_base);
    }
}

/* A face element: each face's vertex index list (and MeshLab's per-corner `texcoord` list, 2 floats a
 * corner, which then replaces the vertices' coordinates) triangulated into the scene. */
static bool ply_read_faces(ply_file *f, const ply_elem *el, bool vertices_seen) {
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    uint32_t material = f->material;
    if (!vertices_seen) return io_error(ctx, f->shown, el->line, "face element before the vertex element");
    for (uint64_t k = 0; k < el->count; k++) {
        ply_sync_line(f);
        uint32_t line = f->line;
        uint64_t n = 0, wedges = 0;
        uint32_t *s = NULL;
        for (size_t i = 0; i < el->prop_n; i++) {
            const ply_prop *pr = &el->props[i];
            double v;
            if ((int)i == el->face_uv) {
                if (!ply_read_list_count(f, pr, &wedges)) return false;
                if (!io_reserve((void **)&f->wedge, &f->wedge_cap, (size_t)wedges + 1, sizeof(float)))
                    return io_error(ctx, f->shown, line, "out of memory");
                for (uint64_t j = 0; j < wedges; j++) {
                    if (!ply_value(f, pr->type, &v)) return false;
                    f->wedge[j] = (float)v;
                    if (!isfinite(f->wedge[j]))
                        return io_error(ctx, f->shown, line, "face %llu: texture coordinate %g is not finite", (unsigned long long)k, v);
                }
                continue;
            }
            if ((int)i != el->face_list) {
                if (pr->count_type != PLY_NONE ? !ply_skip_list(f, pr) : !ply_value(f, pr->type, &v)) return false;
                continue;
            }
            if (!ply_read_list_count(f, pr, &n)) return false;
            if (n < 3)
                return io_error(ctx, f->shown, line, "face %llu has %llu vertices (at least 3 needed)",
                                (unsigned long long)k, (unsigned long long)n);
            if (!(s = io_scratch_u(ctx, 5 * n))) return io_error(ctx, f->shown, line, "out of memory");
            for (uint64_t j = 0; j < n; j++) {
                if (!ply_value(f, pr->type, &v)) return false;
                if (v < 0 || v >= (double)f->vertex_count || v != floor(v))
                    return io_error(ctx, f->shown, line, "face %llu: vertex index %.0f out of range (%llu vertices)",
                                    (unsigned long long)k, v, (unsigned long long)f->vertex_count);
                s[j] = (uint32_t)(f->vertex_base + (size_t)v);
            }
        }
        if (!s) continue; /* no vertex list in this record */
        if (el->face_uv >= 0 && wedges != 2 * n)
            return io_error(ctx, f->shown, line, "face %llu: %llu texture coordinates for %llu corners (2 a corner expected)",
                            (unsigned long long)k, (unsigned long long)wedges, (unsigned long long)n);
        size_t uv0 = b->uv_n;
        if (el->face_uv >= 0) {
            if (b->uv_n + n >= UINT32_MAX || !builder_reserve_texcoords(ctx, (size_t)n))
                return io_error(ctx, f->shown, line, "out of memory");
            memcpy(b->uv + 2 * b->uv_n, f->wedge, 2 * sizeof(float) * (size_t)n);
            b->uv_n += (size_t)n;
        }
        uint32_t *tris = s + n;
        float *pts = n == 3 ? NULL : io_scratch_f(ctx, 3 * n);
        if (n > 3 && !pts) return io_error(ctx, f->shown, line, "out of memory");
        ply_triangulate(b->pos, s, (uint32_t)n, tris, tris + 3 * (n - 2), pts);
        for (uint64_t t = 0; t < n - 2; t++) {
            uint32_t v[3] = {s[tris[3 * t]], s[tris[3 * t + 1]], s[tris[3 * t + 2]]};
            uint32_t nn[3], tt[3];
            ply_corner_indices(f, v, nn, tt);
            if (el->face_uv >= 0)
                for (int j = 0; j < 3; j++) tt[j] = (uint32_t)(uv0 + tris[3 * t + (uint64_t)j]);
            bool uv = f->has_uv || el->face_uv >= 0;
            if (!builder_add_triangle(ctx, v, f->has_normals ? nn : NULL, uv ? tt : NULL, material))
                return io_error(ctx, f->shown, line, "out of memory");
        }
    }
    return true;
}

/* A `tristrips` element (Stanford's and VCG's scans): each list a triangle strip, -1 restarting it;
 * triangle k of a strip is (s[k], s[k+1], s[k+2]), every odd one turned back to the strip's winding.
 * Triangles with a repeated corner (strips stitched together) are left out. */
static bool ply_read_strips(ply_file *f, const ply_elem *el, bool vertices_seen) {
    io_ctx *ctx = f->ctx;
    uint32_t material = f->material;
    if (!vertices_seen) return io_error(ctx, f->shown, el->line, "tristrips element before the vertex element");
    for (uint64_t k = 0; k < el->count; k++) {
        ply_sync_line(f);
        uint32_t line = f->line;
        for (size_t i = 0; i < el->prop_n; i++) {
            const ply_prop *pr = &el->props[i];
            double v;
            if ((int)i != el->face_list) {
                if (pr->count_type != PLY_NONE ? !ply_skip_list(f, pr) : !ply_value(f, pr->type, &v)) return false;
                continue;
            }
            uint64_t n = 0;
            if (!ply_read_list_count(f, pr, &n)) return false;
            uint32_t s[3];
            uint64_t run = 0; /* corners of the current strip so far */
            for (uint64_t j = 0; j < n; j++) {
                if (!ply_value(f, pr->type, &v)) return false;
                if (v == -1.0) {
                    run = 0;
                    continue;
                }
                if (v < 0 || v >= (double)f->vertex_count || v != floor(v))
                    return io_error(ctx, f->shown, line, "strip %llu: vertex index %.0f out of range (%llu vertices)",
                                    (unsigned long long)k, v, (unsigned long long)f->vertex_count);
                s[run % 3] = (uint32_t)(f->vertex_base + (size_t)v);
                if (++run < 3) continue;
                uint64_t t = run - 3; /* the triangle's number in its strip */
                uint32_t a = s[t % 3], b = s[(t + 1) % 3], c = s[(t + 2) % 3];
                if (t & 1) {
                    uint32_t x = a;
                    a = b, b = x;
                }
                if (a == b || b == c || a == c) continue;
                uint32_t tri[3] = {a, b, c}, nn[3], tt[3];
                ply_corner_indices(f, tri, nn, tt);
                if (!builder_add_triangle(ctx, tri, f->has_normals ? nn : NULL, f->has_uv ? tt : NULL, material))
                    return io_error(ctx, f->shown, line, "out of memory");
            }
        }
    }
    return true;
}

/* ---- parallel ASCII --------------------------------------------------------------------------- */

/* A large ASCII file of a vertex element and then a face element (what scanners write: the bunny)
 * is parsed in chunks cut at line starts, on the load's threads, when every record is a line of
 * its own. A first pass counts each chunk's records (its lines that are not blank), so each chunk
 * knows which record its first line holds; the second parses them, vertices straight into the
 * scene's arrays, faces as lists of corners; the third triangulates the faces and writes their
 * triangles in file order. Anything else (a record over two lines, a bad or non-finite value, an
 * index out of range, more or fewer records than declared, an element of another name) leaves the
 * whole body to the serial reader, which writes the error with its own message and line: the
 * result, errors included, is the serial one to the bit. */

typedef struct ply_chunk {
    const char *start, *limit;
    uint64_t first, records; /* its first record's number (vertices first, then faces) and count */
    uint32_t *corners;       /* the faces' vertex indices, scene numbering */
    size_t corner_n, corner_cap;
    uint32_t *faces;         /* first corner of each face; one past the last at faces[face_n] */
    size_t face_n, face_cap, tri_n, t0;
    uint32_t *ring;          /* triangulation scratch for its largest face: tris, ring, points */
    float *pts;
    size_t most;             /* corners of its largest face */
    bool failed;
} ply_chunk;

typedef struct ply_par {
    ply_file *f;
    const ply_elem *vert, *face; /* face NULL: vertices only */
    ply_chunk *chunks;
    uint32_t n;
    const char *end;
    uint32_t material;
} ply_par;

static const char *ply_skip_blank(const char *p) {
    while (io_is_space(*p)) p++;
    return p;
}

static void ply_count_task(void *user, uint32_t index) {
    ply_par *par = user;
    ply_chunk *c = &par->chunks[index];
    for (const char *p = c->start; p < c->limit;) {
        const char *s = ply_skip_blank(p);
        if (s < c->limit && *s != '\n') c->records++;
        const char *nl = s < c->limit ? memchr(s, '\n', (size_t)(c->limit - s)) : NULL;
        p = nl ? nl + 1 : c->limit;
    }
}

/* One vertex record on the line at s into the scene's arrays at vertex k; NULL when it is not one. */
static const char *ply_chunk_vertex(const ply_par *par, const char *s, uint64_t k) {
    const ply_file *f = par->f;
    io_builder *b = &f->ctx->b;
    ply_vertex w = ply_vertex_zero;
    for (size_t i = 0; i < par->vert->prop_n; i++) {
        const ply_prop *pr = &par->vert->props[i];
        double v;
        if (!(s = ply_ascii_token(ply_skip_blank(s), pr->type, &v))) return NULL;
        ply_vertex_value(pr, v, &w);
    }
    if (!ply_vertex_finite(&w)) return NULL;
    memcpy(b->pos + 3 * (b->pos_n + k), w.xyz, sizeof w.xyz);
    if (f->has_normals) memcpy(b->nrm + 3 * (b->nrm_n + k), w.nrm, sizeof w.nrm);
    if (f->has_uv) memcpy(b->uv + 2 * (b->uv_n + k), w.uv, sizeof w.uv);
    if (f->has_color) memcpy(b->col + 3 * (b->pos_n + k), w.rgb, sizeof w.rgb); /* room: ply_par_run */
    return s;
}

/* A list's size at s (no more values than the line could hold); NULL when it is not one. */
static const char *ply_chunk_count(const ply_prop *pr, const char *s, const char *limit, uint64_t *n) {
    double c;
    if (!(s = ply_ascii_token(ply_skip_blank(s), pr->count_type, &c)) || c < 0 || c > (double)(limit - s)) return NULL;
    *n = (uint64_t)c;
    return s;
}

/* One face record on the line at s, its corners appended to the chunk; NULL when it is not one. */
static const char *ply_chunk_face(const ply_par *par, ply_chunk *c, const char *s) {
    const ply_elem *el = par->face;
    const ply_file *f = par->f;
    for (size_t i = 0; i < el->prop_n; i++) {
        const ply_prop *pr = &el->props[i];
        double v;
        uint64_t n = 0;
        if (pr->count_type == PLY_NONE) {
            if (!(s = ply_ascii_token(ply_skip_blank(s), pr->type, &v))) return NULL;
            continue;
        }
        if (!(s = ply_chunk_count(pr, s, c->limit, &n))) return NULL;
        if ((int)i != el->face_list) {
            for (uint64_t j = 0; j < n; j++)
                if (!(s = ply_ascii_token(ply_skip_blank(s), pr->type, &v))) return NULL;
            continue;
        }
        if (n < 3 || c->corner_n + n >= UINT32_MAX ||
            !io_reserve((void **)&c->corners, &c->corner_cap, c->corner_n + n, sizeof(uint32_t)) ||
            !io_reserve((void **)&c->faces, &c->face_cap, c->face_n + 2, sizeof(uint32_t)))
            return NULL;
        for (uint64_t j = 0; j < n; j++) {
            if (!(s = ply_ascii_token(ply_skip_blank(s), pr->type, &v)) || v < 0 || v >= (double)f->vertex_count ||
                v != floor(v))
                return NULL;
            c->corners[c->corner_n + j] = (uint32_t)(f->vertex_base + (size_t)v);
        }
        c->faces[c->face_n++] = (uint32_t)c->corner_n;
        c->corner_n += n;
        c->faces[c->face_n] = (uint32_t)c->corner_n;
        c->tri_n += n - 2;
        if (n > c->most) c->most = n;
    }
    return s;
}

static void ply_parse_task(void *user, uint32_t index) {
    ply_par *par = user;
    ply_chunk *c = &par->chunks[index];
    uint64_t r = c->first, nv = par->vert->count, nf = par->face ? par->face->count : 0;
    for (const char *p = c->start; p < c->limit && !c->failed;) {
        const char *s = ply_skip_blank(p);
        if (s < c->limit && *s != '\n') {
            s = r < nv ? ply_chunk_vertex(par, s, r) : r - nv < nf ? ply_chunk_face(par, c, s) : NULL;
            if (s) s = ply_skip_blank(s);
            c->failed = !s || !(*s == '\n' || s == par->end);
            r++;
        }
        const char *nl = s && s < c->limit ? memchr(s, '\n', (size_t)(c->limit - s)) : NULL;
        p = nl ? nl + 1 : c->limit;
    }
    if (!c->failed && c->most > 3) { /* the scratch now, so the fill cannot fail */
        c->ring = io_malloc(4 * c->most * sizeof(uint32_t));
        c->pts = io_malloc(3 * c->most * sizeof(float));
        c->failed = !c->ring || !c->pts;
    }
}

static void ply_fill_task(void *user, uint32_t index) {
    const ply_par *par = user;
    const ply_chunk *c = &par->chunks[index];
    const ply_file *f = par->f;
    io_builder *b = &f->ctx->b;
    uint32_t tri3[3];
    size_t t = c->t0;
    for (size_t i = 0; i < c->face_n; i++) {
        const uint32_t *s = c->corners + c->faces[i];
        uint32_t n = c->faces[i + 1] - c->faces[i], *tris = n == 3 ? tri3 : c->ring;
        ply_triangulate(b->pos, s, n, tris, tris + 3 * (n - 2), c->pts);
        for (uint32_t k = 0; k < n - 2; k++, t++) {
            uint32_t v[3] = {s[tris[3 * k]], s[tris[3 * k + 1]], s[tris[3 * k + 2]]}, nn[3], tt[3];
            ply_corner_indices(f, v, nn, tt);
            memcpy(b->idx + 3 * t, v, sizeof v);
            if (b->nidx) memcpy(b->nidx + 3 * t, nn, sizeof nn);
            if (b->tidx) memcpy(b->tidx + 3 * t, tt, sizeof tt);
            b->mat[t] = par->material;
        }
    }
}

/* The vertex and face elements parsed in parallel; false (with nothing changed but room reserved,
 * and no error written) when the serial reader is to parse them. */
static bool ply_par_run(ply_par *par) {
    ply_file *f = par->f;
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    const char **starts = io_malloc(par->n * sizeof *starts);
    if (!starts) return false;
    par->n = io_split_lines(f->p, (size_t)(f->end - f->p), par->n, starts);
    for (uint32_t i = 0; i < par->n; i++) {
        par->chunks[i].start = starts[i];
        par->chunks[i].limit = i + 1 < par->n ? starts[i + 1] : f->end;
    }
    free(starts);
    io_parallel_for(ctx->threads, par->n, ply_count_task, par);
    uint64_t records = 0;
    for (uint32_t i = 0; i < par->n; i++) par->chunks[i].first = records, records += par->chunks[i].records;
    if (records != par->vert->count + (par->face ? par->face->count : 0)) return false;
    if (par->vert->count > UINT32_MAX - b->pos_n || !ply_reserve_vertices(f, par->vert) ||
        b->pos_cap - b->pos_n < par->vert->count)
        return false;
    /* colours for every vertex of the element (the last one's set white here, the parse overwrites) */
    static const float white[3] = {1, 1, 1};
    if (f->has_color && par->vert->count && !builder_set_colors(ctx, b->pos_n + par->vert->count - 1, white, 1))
        return false;
    f->vertex_base = b->pos_n;
    f->vertex_count = par->vert->count;
    io_parallel_for(ctx->threads, par->n, ply_parse_task, par);
    size_t tris = 0;
    for (uint32_t i = 0; i < par->n; i++) {
        if (par->chunks[i].failed) return false;
        par->chunks[i].t0 = b->tri_n + tris;
        tris += par->chunks[i].tri_n;
    }
    par->material = f->material;
    /* from here on the serial reader's result: vertices counted, then the triangles */
    size_t nv = (size_t)par->vert->count;
    b->pos_n += nv;
    if (f->has_normals) b->nrm_n += nv;
    if (f->has_uv) b->uv_n += nv;
    if (!builder_claim_triangles(ctx, tris, f->has_normals && tris, f->has_uv && tris)) {
        io_error(ctx, f->shown, par->face ? par->face->line : par->vert->line, "out of memory");
        return true;
    }
    io_parallel_for(ctx->threads, par->n, ply_fill_task, par);
    ctx->chunks_taken += par->n;
    f->p = f->end;
    return true;
}

/* Parses the body in parallel when it suits (see above); true when it did (ctx->failed after an
 * out-of-memory error), false when the serial reader is to. */
static bool ply_par_load(ply_file *f) {
    io_ctx *ctx = f->ctx;
    ply_par par = {.f = f, .end = f->end};
    if (f->format != PLY_ASCII || f->elem_n < 1 || f->elem_n > 2 || strcmp(f->elems[0].name, "vertex") != 0) return false;
    par.vert = &f->elems[0];
    for (size_t i = 0; i < par.vert->prop_n; i++)
        if (par.vert->props[i].count_type != PLY_NONE) return false;
    if (f->elem_n == 2) {
        par.face = &f->elems[1];
        if (strcmp(par.face->name, "face") != 0 || par.face->face_list < 0 || par.face->face_uv >= 0) return false;
    }
    if (!ply_vertex_uses(f, par.vert)) return false;
    par.n = io_chunk_count(ctx, (size_t)(f->end - f->p));
    if (par.n < 2 || !(par.chunks = io_calloc(par.n, sizeof *par.chunks))) return false;
    bool done = ply_par_run(&par);
    for (uint32_t i = 0; i < par.n; i++) {
        free(par.chunks[i].corners);
        free(par.chunks[i].faces);
        free(par.chunks[i].ring);
        free(par.chunks[i].pts);
    }
    free(par.chunks);
    return done;
}

/* Declared counts against the bytes after the header, before any allocation or loop: every record
 * takes at least one byte per binary value (its size) or two per ASCII value (a digit and a
 * separator), so a count the file cannot hold, or records of no properties (which would loop over a
 * count of 10^12 reading nothing), are errors at the element's line. */
static bool ply_check_counts(ply_file *f) {
    uint64_t left = (uint64_t)(f->end - f->p) + 1; /* +1: the last value may lack its separator */
    for (size_t i = 0; i < f->elem_n; i++) {
        const ply_elem *el = &f->elems[i];
        if (el->count == 0) continue;
        if (el->prop_n == 0)
            return io_error(f->ctx, f->shown, el->line, "element '%s' declares %llu records but no properties",
                            el->name, (unsigned long long)el->count);
        uint64_t min = 0;
        for (size_t j = 0; j < el->prop_n; j++) {
            const ply_prop *pr = &el->props[j];
            min += f->format == PLY_ASCII ? 2 : ply_size(pr->count_type != PLY_NONE ? pr->count_type : pr->type);
        }
        if (el->count > left / min)
            return io_error(f->ctx, f->shown, el->line,
                            "element '%s' declares %llu records of at least %llu bytes: more than the %llu bytes "
                            "the file has left (truncated, or a wrong count)",
                            el->name, (unsigned long long)el->count, (unsigned long long)min,
                            (unsigned long long)(left - 1));
        left -= el->count * min;
    }
    return true;
}

static void ply_free(ply_file *f) {
    for (size_t i = 0; i < f->elem_n; i++) free(f->elems[i].props);
    free(f->elems);
    free(f->wedge);
}

/* The faces' material: MeshLab's `comment TextureFile` as a diffuse texture (white, as MeshLab shows
 * it) when the file has texture coordinates to map it with; a texture that is not there is a
 * warning (it is a comment, not part of the format), one that cannot be decoded an error. */
static bool ply_material(ply_file *f, const char *path) {
    io_ctx *ctx = f->ctx;
    bool uvs = false;
    for (size_t i = 0; i < f->elem_n; i++) {
        const ply_elem *el = &f->elems[i];
        uvs |= el->face_uv >= 0;
        for (size_t j = 0; strcmp(el->name, "vertex") == 0 && j < el->prop_n; j++)
            uvs |= el->props[j].use == PLY_USE_U || el->props[j].use == PLY_USE_V;
    }
    f->material = IO_NONE;
    if (f->texture[0] && uvs) {
        char name[256], full[IO_PATH_MAX];
        snprintf(name, sizeof name, "%s", f->texture);
        for (char *c = name; *c; c++)
            if (*c == '\\') *c = '/';
        vfs_join(&ctx->vfs, path, name, full, sizeof full);
        if (!vfs_exists(ctx, full)) {
            io_warning(ctx, f->shown, f->texture_line, "TextureFile '%s' not found; the mesh is left untextured", f->texture);
        } else {
            uint32_t t = tex_load(ctx, full, name, f->shown, f->texture_line);
            if (t == IO_NONE) return false;
            rp_material_data m;
            builder_material_defaults(&m, "TextureFile");
            m.kd[0] = m.kd[1] = m.kd[2] = 1.0f;
            m.map_kd = (int32_t)t;
            if ((f->material = builder_add_material(ctx, &m)) == IO_NONE) return io_error(ctx, f->shown, 0, "out of memory");
        }
    }
    if (f->material == IO_NONE && (f->material = builder_default_material(ctx)) == IO_NONE)
        return io_error(ctx, f->shown, 0, "out of memory");
    return true;
}

bool ply_load(io_ctx *ctx, const char *path) {
    ply_file f;
    memset(&f, 0, sizeof f);
    f.ctx = ctx;
    f.line = 1;
    vfs_display(&ctx->vfs, path, f.shown, sizeof f.shown);
    io_buf buf;
    if (!vfs_read(ctx, path, &buf)) return io_error(ctx, f.shown, 0, "cannot open: %s", ctx->why);
    ctx->bytes += buf.size;
    f.p = buf.data;
    f.end = buf.data + buf.size;
    bool ok = ply_read_header(&f) && ply_check_counts(&f) && ply_material(&f, path);
    const char *body = f.p;
    uint32_t body_line = f.line;
    if (ok && ply_par_load(&f)) {
        ok = !ctx->failed;
        ply_free(&f);
        vfs_buf_free(&buf);
        return ok;
    }
    f.p = body, f.line = body_line, f.has_normals = f.has_uv = f.has_color = false;
    bool vertices_seen = false;
    /* Elements may come in any order: faces (or strips) before the vertices are read past and
     * come back once the vertices are in (where they start, and on which line). */
    const char *early_p[2] = {NULL, NULL};
    uint32_t early_line[2] = {0, 0};
    size_t early_el[2] = {0, 0}, early_n = 0;
    for (size_t i = 0; ok && i < f.elem_n; i++) {
        const ply_elem *el = &f.elems[i];
        bool faces = strcmp(el->name, "face") == 0 && el->face_list >= 0;
        bool strips = strcmp(el->name, "tristrips") == 0 && el->face_list >= 0;
        if (strcmp(el->name, "vertex") == 0 && !vertices_seen) {
            ok = ply_read_vertices(&f, el);
            vertices_seen = true;
            for (size_t k = 0; ok && k < early_n; k++) {
                const char *here = f.p;
                uint32_t line = f.line;
                const ply_elem *fe = &f.elems[early_el[k]];
                f.p = early_p[k], f.line = early_line[k];
                ok = strcmp(fe->name, "face") == 0 ? ply_read_faces(&f, fe, true) : ply_read_strips(&f, fe, true);
                f.p = here, f.line = line;
            }
        } else if (faces && vertices_seen) {
            ok = ply_read_faces(&f, el, vertices_seen);
        } else if (strips && vertices_seen) {
            ok = ply_read_strips(&f, el, vertices_seen);
        } else {
            if ((faces || strips) && early_n < 2) {
                early_p[early_n] = f.p, early_line[early_n] = f.line, early_el[early_n++] = i;
            } else if (faces || strips) {
                ok = io_error(ctx, f.shown, el->line, "more than two face elements before the vertex element");
                break;
            }
            for (uint64_t k = 0; ok && k < el->count; k++)
                for (size_t j = 0; ok && j < el->prop_n; j++) {
                    double v;
                    const ply_prop *pr = &el->props[j];
                    ok = pr->count_type != PLY_NONE ? ply_skip_list(&f, pr) : ply_value(&f, pr->type, &v);
                }
        }
    }
    if (ok && !vertices_seen) ok = io_error(ctx, f.shown, f.line, "no vertex element");
    if (ok && f.format == PLY_ASCII) {
        /* Anything but blanks after the last element means the counts were wrong. */
        const char *p = f.p;
        while (p < f.end && (io_is_space(*p) || *p == '\n')) {
            if (*p == '\n') f.line++;
            p++;
        }
        if (p < f.end) ok = io_error(ctx, f.shown, f.line, "data after the last element (element counts too small?)");
    } else if (ok && f.p != f.end) {
        ok = io_error(ctx, f.shown, f.line, "%zu bytes after the last element (element counts too small?)",
                      (size_t)(f.end - f.p));
    }
    ply_free(&f);
    vfs_buf_free(&buf);
    return ok;
}
