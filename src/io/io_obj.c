/* Wavefront OBJ and MTL: one pass over the file in memory, line by line. Positions, normals and
 * texture coordinates go to the builder as they come (OBJ indexes them globally, so the builder's
 * arrays are the file's); faces are triangulated as they are read. Objects, groups and smoothing
 * groups do not change the geometry and are skipped. */
#include <math.h>
#include <stdio.h>
#include <strings.h>

#include "io/io_internal.h"

typedef struct obj_file {
    io_ctx *ctx;
    const char *path; /* as the vfs knows it */
    char shown[IO_PATH_MAX + 256];
    uint32_t line;
} obj_file;

static const char *skip_blank(const char *p) {
    while (*p == ' ' || *p == '\t') p++;
    return p;
}

static bool at_eol(const char *p) { return *p == '\n' || *p == '\r' || *p == '\0' || *p == '#'; }

static bool is_delim(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\0'; }

static const char *next_line(const char *p, const char *end) {
    while (p < end && *p != '\n') p++;
    return p < end ? p + 1 : end;
}

/* Where the line at p ends ('\n' or end), and whether its last character (before a '\r') is a
 * backslash: the OBJ spec's line continuation. */
static const char *line_end(const char *p, const char *end, bool *continued) {
    const char *e = memchr(p, '\n', (size_t)(end - p));
    if (!e) e = end;
    const char *t = e > p && e[-1] == '\r' ? e - 1 : e;
    *continued = t > p && t[-1] == '\\';
    return e;
}

/* Reads one float after blanks; NULL (with the error written) when there is none. */
static const char *obj_float(obj_file *f, const char *p, float *v, const char *what) {
    p = skip_blank(p);
    const char *q = io_parse_float(p, v);
    if (!q || !is_delim(*q)) {
        int len = 0;
        while (len < 24 && !is_delim(p[len])) len++;
        io_error(f->ctx, f->shown, f->line, "%s: expected a finite number, got '%.*s'", what, len, p);
        return NULL;
    }
    return q;
}

/* A vertex colour after `v x y z` (q just past z): `r g b` or `w r g b` (MeshLab's and
 * tinyobjloader's extension), sRGB-decoded into rgb; false when the line has no such colour (a bare
 * w, or nothing: the rest is left to the caller as before). */
static bool obj_vertex_color(const char *q, float rgb[3]) {
    float e[4];
    int n = 0;
    for (; n < 4; n++) {
        const char *r = io_parse_float(skip_blank(q), &e[n]);
        if (!r || !is_delim(*r)) break;
        q = r;
    }
    if (n < 3) return false;
    for (int k = 0; k < 3; k++) rgb[k] = io_srgb_to_linear(e[n - 3 + k]);
    return true;
}

/* The rest of the line without surrounding blanks, copied into out. */
static const char *rest_of_line(const char *p, char *out, size_t size) {
    p = skip_blank(p);
    const char *s = p;
    while (*p != '\n' && *p != '\0') p++;
    const char *e = p;
    while (e > s && (e[-1] == ' ' || e[-1] == '\t' || e[-1] == '\r')) e--;
    size_t n = (size_t)(e - s);
    if (n >= size) n = size - 1;
    memcpy(out, s, n);
    out[n] = '\0';
    return p;
}

/* Cuts a comment that follows a name after a blank ("usemtl red  # walls", "map_Kd a.png # diffuse")
 * off s; false when there is none. Names keep their blanks, and a name may hold " #" itself (3ds
 * Max's "Material #25"), so callers try the whole name first and this one only when that fails. */
static bool cut_comment(char *s) {
    for (char *c = s; *c; c++)
        if (*c == '#' && c > s && (c[-1] == ' ' || c[-1] == '\t')) {
            while (c > s && (c[-1] == ' ' || c[-1] == '\t')) c--;
            *c = '\0';
            return true;
        }
    return false;
}

static bool word_is(const char *p, const char *w) {
    size_t n = strlen(w);
    return strncmp(p, w, n) == 0 && is_delim(p[n]);
}

/* ---- MTL -------------------------------------------------------------------------------------- */

typedef struct mtl_pending {
    bool active;
    rp_material_data m;
    float d, tr;
    bool has_d, has_tr; /* d wins over Tr, whichever comes first (tinyobjloader) */
    bool has_tf;
    float tf[3];
    /* the texture statements' -s and -o (scale u v, offset u v), for the material's one transform */
    struct {
        float so[4];
        uint32_t line;
        bool kd;
    } maps[8];
    uint32_t map_n;
    uint32_t bump;        /* the bump map's height texture, IO_NONE: none */
    float bump_scale;     /* its -bm */
    uint32_t bump_line;
} mtl_pending;

/* The material's texture transform: map_Kd's -s and -o, else those of its first texture; a texture
 * whose options differ is read with these too, and a warning says so (once a material). */
static void mtl_uv_transform(obj_file *f, mtl_pending *pm) {
    uint32_t pick = 0;
    for (uint32_t i = 0; i < pm->map_n; i++)
        if (pm->maps[i].kd) {
            pick = i;
            break;
        }
    if (pm->map_n == 0) return;
    const float *so = pm->maps[pick].so;
    for (uint32_t i = 0; i < pm->map_n; i++)
        if (memcmp(pm->maps[i].so, so, sizeof pm->maps[i].so) != 0) {
            io_warning(f->ctx, f->shown, pm->maps[i].line,
                       "material '%s': this texture's -s/-o differ from those of line %u; one transform a material: that one's is used",
                       pm->m.name, pm->maps[pick].line);
            break;
        }
    if (so[0] == 1.0f && so[1] == 1.0f && so[2] == 0.0f && so[3] == 0.0f) return;
    /* (u, v) -> (s_u u + o_u, s_v v + o_v), as Blender's importer maps them */
    const float t[6] = {so[0], 0.0f, so[2], 0.0f, so[1], so[3]};
    pm->m.uv_transform = true;
    memcpy(pm->m.uv_matrix, t, sizeof t);
}

/* Derives kr and kt from illum, d and Tf as the MTL spec's illumination models use them; the bump
 * map becomes the normal map (norm wins over it); the texture transform. */
static bool mtl_finish(obj_file *f, mtl_pending *pm) {
    if (!pm->active) return true;
    io_ctx *ctx = f->ctx;
    rp_material_data *m = &pm->m;
    if (pm->bump != IO_NONE) {
        int kind = m->map_normal ? TEX_BUMP_HEIGHT : tex_bump_kind(ctx, pm->bump);
        if (m->map_normal) {
            io_warning(ctx, f->shown, pm->bump_line, "material '%s' has both norm and a bump map; the bump map is not used", m->name);
        } else if (kind == TEX_BUMP_NORMALS) {
            io_warning(ctx, f->shown, pm->bump_line,
                       "material '%s': the bump map is coloured like a tangent-space normal map (as Blender writes them); read as one",
                       m->name);
            m->map_normal = (int32_t)pm->bump + 1;
        } else if (kind == TEX_BUMP_HEIGHT && pm->bump_scale != 0.0f) { /* a flat one has no normal to give */
            uint32_t t = tex_bump_to_normal(ctx, pm->bump, pm->bump_scale, f->shown, pm->bump_line);
            if (t == IO_NONE) return false;
            m->map_normal = (int32_t)t + 1;
        }
    }
    mtl_uv_transform(f, pm);
    int il = m->illum;
    if (il == 3 || il == 5 || il == 7) memcpy(m->kr, m->ks, sizeof m->kr);
    /* Tr is 1 - d (an extension, not in the spec); with both, d counts: 3ds Max's exporter wrote
     * "d 1" beside "Tr 1" for opaque surfaces. */
    float d = pm->has_d ? pm->d : pm->has_tr ? 1.0f - pm->tr : 1.0f;
    if (pm->has_tf && (il == 4 || il == 6 || il == 7 || il == 9)) {
        memcpy(m->kt, pm->tf, sizeof m->kt);
    } else if (d < 1.0f) {
        m->kt[0] = m->kt[1] = m->kt[2] = 1.0f - d;
    }
    pm->active = false;
    if (builder_add_material(ctx, m) == IO_NONE) return io_error(ctx, f->shown, f->line, "out of memory");
    return true;
}

static bool mtl_color(obj_file *f, const char **pp, float c[3], const char *what) {
    const char *p = skip_blank(*pp);
    /* The spec's other two forms: "Kd spectral file.rfl [factor]" (a reflectance curve, not read:
     * the colour stays as it was) and "Kd xyz x [y z]" (CIE XYZ, to linear sRGB, D65). */
    if (word_is(p, "spectral")) {
        io_warning(f->ctx, f->shown, f->line, "%s spectral: .rfl curves are not read; the colour is left as it was", what);
        return true;
    }
    bool xyz = word_is(p, "xyz");
    if (xyz) p += 3;
    if (!(p = obj_float(f, p, &c[0], what))) return false;
    /* "Kd r" alone means grey r. */
    const char *q = skip_blank(p);
    if (at_eol(q)) {
        c[1] = c[2] = c[0];
    } else if (!(p = obj_float(f, p, &c[1], what)) || !(p = obj_float(f, p, &c[2], what))) {
        return false;
    }
    if (xyz) {
        float x = c[0], y = c[1], z = c[2];
        c[0] = fmaxf(0.0f, 3.2404542f * x - 1.5371385f * y - 0.4985314f * z);
        c[1] = fmaxf(0.0f, -0.9692660f * x + 1.8760108f * y + 0.0415560f * z);
        c[2] = fmaxf(0.0f, 0.0556434f * x - 0.2040259f * y + 1.0572252f * z);
    }
    /* a negative colour rendered negative radiance (Whitted's image had pixels below 0) */
    for (int k = 0; k < 3; k++)
        if (c[k] < 0.0f) return io_error(f->ctx, f->shown, f->line, "%s: negative colour component %g (expected >= 0)", what, (double)c[k]);
    *pp = p;
    return true;
}

/* A texture named by a path that is not there, absolute ("C:/Users/me/wood.png", "/home/me/wood.png":
 * the exporter's disk) or relative to another folder, is looked for by its file name beside the
 * MTL file, as Blender's importer does; found there, full becomes that path and a warning says
 * so. Otherwise full stays, and tex_load reports the path as written. */
static void mtl_texture_fallback(obj_file *f, const char *mtl, const char *name, char *full, size_t size) {
    io_ctx *ctx = f->ctx;
    const char *base = strrchr(name, '/');
    if (!base || vfs_exists(ctx, full)) return;
    char near[IO_PATH_MAX];
    vfs_join(&ctx->vfs, mtl, base + 1, near, sizeof near);
    if (!vfs_exists(ctx, near)) return;
    io_warning(ctx, f->shown, f->line, "texture '%s' not found there; using '%s' beside the material library", name, base + 1);
    snprintf(full, size, "%s", near);
}

/* A statement's keyword as the parser spells it: keywords are matched without regard to case, as
 * Blender's importer does (some exporters write "KD", "Map_Kd", "NEWMTL"; tinyobjloader ignored
 * them, and so did raypack: the material rendered default grey). p, kw: the keyword as written;
 * returns it unchanged when it is no keyword the parser reads. */
static const char *mtl_keyword(const char *p, size_t kw) {
    static const char *const words[] = {"Kd", "Ks", "Ke", "Ka", "Tf", "Ns", "Ni", "d", "Tr", "illum", "map_Kd",
                                        "map_Pr", "map_Ke", "map_d", "map_Ks", "norm", "bump", "map_bump"};
    for (size_t i = 0; i < sizeof words / sizeof words[0]; i++)
        if (strlen(words[i]) == kw && strncasecmp(p, words[i], kw) == 0) return words[i];
    return p;
}

static bool mtl_parse(io_ctx *ctx, const char *path, const char *shown, const io_buf *buf) {
    obj_file f = {.ctx = ctx, .path = path, .line = 1};
    snprintf(f.shown, sizeof f.shown, "%s", shown);
    const char *end = buf->data + buf->size, *p = io_skip_bom(buf->data, end);
    mtl_pending pm;
    memset(&pm, 0, sizeof pm);
    for (; p < end; p = next_line(p, end), f.line++) {
        p = skip_blank(p);
        if (at_eol(p)) continue;
        if (strncasecmp(p, "newmtl", 6) == 0 && is_delim(p[6])) { /* p[6] read only when p[0..5] are not the NUL */
            if (!mtl_finish(&f, &pm)) return false;
            char name[256];
            rest_of_line(p + 6, name, sizeof name);
            builder_material_defaults(&pm.m, name);
            pm.m.illum = 2;
            pm.d = 1.0f;
            pm.has_d = pm.has_tr = false;
            pm.has_tf = false;
            pm.map_n = 0;
            pm.bump = IO_NONE;
            pm.active = true;
            continue;
        }
        if (!pm.active) continue; /* statements before the first newmtl have no material */
        const char *q = p;
        while (!is_delim(*q)) q++;
        size_t kw = (size_t)(q - p);
        const char *kp = mtl_keyword(p, kw);
        rp_material_data *m = &pm.m;
        if (kw == 2 && kp[0] == 'K' && (kp[1] == 'd' || kp[1] == 's' || kp[1] == 'e' || kp[1] == 'a')) {
            float *dst = kp[1] == 'd' ? m->kd : kp[1] == 's' ? m->ks : kp[1] == 'e' ? m->ke : m->ka;
            if (!mtl_color(&f, &q, dst, kp[1] == 'd' ? "Kd" : kp[1] == 's' ? "Ks" : kp[1] == 'e' ? "Ke" : "Ka"))
                return false;
        } else if (kw == 2 && kp[0] == 'T' && kp[1] == 'f') {
            if (!mtl_color(&f, &q, pm.tf, "Tf")) return false;
            pm.has_tf = true;
        } else if (kw == 2 && kp[0] == 'N' && kp[1] == 's') {
            if (!obj_float(&f, q, &m->ns, "Ns")) return false;
        } else if (kw == 2 && kp[0] == 'N' && kp[1] == 'i') {
            if (!obj_float(&f, q, &m->ior, "Ni")) return false;
        } else if (kw == 1 && kp[0] == 'd') {
            const char *r = skip_blank(q);
            if (word_is(r, "-halo")) r += 5; /* the spec's halo dissolve: taken as the plain one */
            if (!obj_float(&f, r, &pm.d, "d")) return false;
            pm.has_d = true;
        } else if (kw == 2 && kp[0] == 'T' && kp[1] == 'r') {
            if (!obj_float(&f, q, &pm.tr, "Tr")) return false;
            pm.has_tr = true;
        } else if (kw == 5 && strncmp(kp, "illum", 5) == 0) {
            int64_t il;
            const char *r = io_parse_int(skip_blank(q), &il);
            if (!r || !is_delim(*r) || il < 0 || il > 10)
                return io_error(ctx, f.shown, f.line, "illum: expected an integer 0-10");
            m->illum = (int32_t)il;
        } else if ((kw == 6 && strncmp(kp, "map_Kd", 6) == 0) || (kw == 6 && strncmp(kp, "map_Pr", 6) == 0) ||
                   (kw == 6 && strncmp(kp, "map_Ke", 6) == 0) || (kw == 5 && strncmp(kp, "map_d", 5) == 0) ||
                   (kw == 6 && strncmp(kp, "map_Ks", 6) == 0) || (kw == 4 && strncmp(kp, "norm", 4) == 0) ||
                   (kw == 4 && strncmp(kp, "bump", 4) == 0) ||
                   (kw == 8 && (strncmp(kp, "map_bump", 8) == 0 || strncmp(kp, "map_Bump", 8) == 0))) {
            /* Options (-s 1 1 1, -clamp on, ...) come before the file name; the name is the rest.
             * -s and -o (u and v; w has no use on a surface) give the material's texture
             * transform, -bm a bump map's scale, -clamp on this texture's clamp-to-edge wrapping
             * and -mm base gain its values' remap (tex_sampler); -t (turbulence) is not applied:
             * a warning says so, where it is not its default. */
            const char *r = skip_blank(q);
            float so[4] = {1.0f, 1.0f, 0.0f, 0.0f}, bm = 1.0f;
            tex_sampler smp = TEX_SAMPLER_DEFAULT;
            while (*r == '-') {
                const char *o = r;
                while (!is_delim(*r)) r++;
                bool uv = word_is(o, "-s") || word_is(o, "-o");
                bool xyz = uv || word_is(o, "-t"), mm = word_is(o, "-mm");
                /* options whose first argument is a number (the spec's; -clamp, -imfchan, -type
                 * and the like take words) */
                bool numeric = xyz || mm || word_is(o, "-bm") || word_is(o, "-boost") || word_is(o, "-texres");
                int args = xyz ? 3 : mm ? 2 : 1;
                bool changes = false;
                int olen = 0;
                while (!is_delim(o[olen])) olen++;
                for (int k = 0; k < args; k++) {
                    r = skip_blank(r);
                    int len = 0;
                    while (len < 24 && !is_delim(r[len])) len++;
                    float v;
                    const char *e = io_parse_float(r, &v);
                    bool num = e && is_delim(*e);
                    if (k == 0 && !num && numeric)
                        return io_error(ctx, f.shown, f.line, "%.*s option %.*s: expected a finite number, got '%.*s'",
                                        (int)kw, p, olen, o, len, r);
                    if (k > 0 && !num) break; /* -s may give fewer than 3, -mm its base alone */
                    if (num && uv) {
                        if (k < 2) so[(o[1] == 'o' ? 2 : 0) + k] = v;
                    } else if (num && word_is(o, "-bm")) {
                        bm = v;
                    } else if (num && mm) {
                        *(k == 0 ? &smp.mm_base : &smp.mm_gain) = v;
                    } else if (num && xyz) {
                        changes |= v != 0.0f; /* -t */
                    } else if (word_is(o, "-clamp")) {
                        bool on = word_is(r, "on"), off = word_is(r, "off");
                        if (!on && !off)
                            return io_error(ctx, f.shown, f.line, "%.*s option -clamp: expected on or off, got '%.*s'",
                                            (int)kw, p, len, r);
                        smp.wrap_u = smp.wrap_v = on ? RP_TEXTURE_CLAMP : RP_TEXTURE_REPEAT;
                    }
                    while (!is_delim(*r)) r++;
                }
                if (changes) {
                    const char *e = r;
                    while (e > o && (e[-1] == ' ' || e[-1] == '\t')) e--;
                    io_warning(ctx, f.shown, f.line, "%.*s option '%.*s' is not applied (the texture is mapped without it)",
                               (int)kw, p, (int)(e - o), o);
                }
                r = skip_blank(r);
            }
            char name[IO_PATH_MAX], full[IO_PATH_MAX];
            rest_of_line(r, name, sizeof name);
            for (char *c = name; *c; c++)
                if (*c == '\\') *c = '/';
            vfs_join(&ctx->vfs, path, name, full, sizeof full);
            if (!vfs_exists(ctx, full) && cut_comment(name)) vfs_join(&ctx->vfs, path, name, full, sizeof full);
            if (!name[0]) return io_error(ctx, f.shown, f.line, "%.*s without a file name", (int)kw, p);
            mtl_texture_fallback(&f, path, name, full, sizeof full);
            uint32_t t = tex_load(ctx, full, name, f.shown, f.line);
            if (t == IO_NONE || (t = tex_sampled(ctx, t, &smp, f.shown, f.line)) == IO_NONE) return false;
            if (pm.map_n < sizeof pm.maps / sizeof pm.maps[0]) {
                memcpy(pm.maps[pm.map_n].so, so, sizeof so);
                pm.maps[pm.map_n].line = f.line;
                pm.maps[pm.map_n++].kd = kp[4] == 'K' && kp[5] == 'd';
            }
            if (kw == 5) {
                /* alpha cutout (leaves, fences): the texture's alpha channel, or its red channel
                 * where it has none, below 0.5 cuts the surface out */
                m->map_alpha = (int32_t)t + 1;
                m->alpha_mode = RP_ALPHA_MASK;
            } else if (kp[0] == 'n') m->map_normal = (int32_t)t + 1;    /* PBR extension: tangent-space normals */
            else if (kp[0] == 'b' || kp[4] == 'b' || kp[4] == 'B') {      /* a height map, made a normal map at the end */
                pm.bump = t, pm.bump_scale = bm, pm.bump_line = f.line;
            } else if (kp[5] == 'r') m->map_roughness = (int32_t)t + 1; /* PBR extension: roughness */
            else if (kp[5] == 'e') m->map_ke = (int32_t)t + 1;          /* emission texture */
            else if (kp[5] == 's') m->map_ks = (int32_t)t + 1;          /* specular colour, times Ks */
            else m->map_kd = (int32_t)t;
        }
        /* Everything else (map_Ns, map_Ka, PBR extensions...) has no field in rp_material_data. */
    }
    if (!mtl_finish(&f, &pm)) return false;
    ctx->bytes += buf->size;
    return true;
}

/* ---- OBJ -------------------------------------------------------------------------------------- */

/* Statements of the OBJ spec that carry no triangle data: accepted and skipped. */
static bool obj_skippable(const char *p) {
    static const char *const words[] = {"o", "g", "s", "l", "p", "vp", "cstype", "deg", "bmat", "step",
                                        "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp",
                                        "end", "con", "mg", "bevel", "c_interp", "d_interp", "lod",
                                        "shadow_obj", "trace_obj", "ctech", "stech", "maplib", "usemap",
                                        "call", "csh"};
    for (size_t i = 0; i < sizeof words / sizeof words[0]; i++)
        if (word_is(p, words[i])) return true;
    return false;
}

static bool obj_index(obj_file *f, int64_t raw, size_t count, const char *what, uint32_t *out) {
    int64_t i;
    if (raw > 0)
        i = raw - 1;
    else if (raw < 0)
        i = (int64_t)count + raw;
    else
        return io_error(f->ctx, f->shown, f->line, "%s index 0 is invalid (OBJ indices start at 1)", what);
    if (i < 0 || (uint64_t)i >= count)
        return io_error(f->ctx, f->shown, f->line, "%s index %lld out of range (%zu defined so far)", what,
                        (long long)raw, count);
    *out = (uint32_t)i;
    return true;
}

static bool obj_face(obj_file *f, const char *p, uint32_t material) {
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    uint32_t n = 0;
    uint32_t *c = NULL; /* corners: v, t, n per vertex */
    for (;;) {
        p = skip_blank(p);
        if (at_eol(p)) break;
        if (!(c = io_scratch_u(ctx, 7 * ((size_t)n + 1) + 8)))
            return io_error(ctx, f->shown, f->line, "out of memory");
        int64_t raw;
        const char *q = io_parse_int(p, &raw);
        if (!q) return io_error(ctx, f->shown, f->line, "bad face vertex '%.*s'", (int)strcspn(p, " \t\r\n"), p);
        uint32_t *corner = c + 3 * n;
        corner[1] = corner[2] = IO_NONE;
        if (!obj_index(f, raw, b->pos_n, "vertex", &corner[0])) return false;
        if (*q == '/') {
            q++;
            if (*q != '/') {
                if (!(q = io_parse_int(q, &raw)))
                    return io_error(ctx, f->shown, f->line, "bad texture coordinate index in face");
                if (!obj_index(f, raw, b->uv_n, "texture coordinate", &corner[1])) return false;
            }
            if (*q == '/') {
                q++;
                if (!(q = io_parse_int(q, &raw))) return io_error(ctx, f->shown, f->line, "bad normal index in face");
                if (!obj_index(f, raw, b->nrm_n, "normal", &corner[2])) return false;
            }
        }
        if (!is_delim(*q) && *q != '#')
            return io_error(ctx, f->shown, f->line, "bad face vertex '%.*s'", (int)strcspn(p, " \t\r\n"), p);
        p = q;
        if (++n >= (1u << 24)) return io_error(ctx, f->shown, f->line, "face has too many vertices");
    }
    if (n < 3) return io_error(ctx, f->shown, f->line, "face with %u vertices (at least 3 needed)", n);
    if (material == IO_NONE && (material = builder_default_material(ctx)) == IO_NONE)
        return io_error(ctx, f->shown, f->line, "out of memory");
    if (!builder_reserve_triangles(ctx, n - 2)) return io_error(ctx, f->shown, f->line, "out of memory");
    uint32_t *tris = c + 3 * n, *ring = tris + 3 * (n - 2);
    if (n == 3) {
        tris[0] = 0, tris[1] = 1, tris[2] = 2;
    } else {
        float *pts = io_scratch_f(ctx, 3 * (size_t)n);
        if (!pts) return io_error(ctx, f->shown, f->line, "out of memory");
        for (uint32_t i = 0; i < n; i++) memcpy(pts + 3 * i, b->pos + 3 * (size_t)c[3 * i], 3 * sizeof(float));
        poly_triangulate(pts, n, tris, ring);
    }
    for (uint32_t k = 0; k < n - 2; k++) {
        uint32_t v[3], t[3], nn[3];
        bool has_t = true, has_n = true;
        for (int j = 0; j < 3; j++) {
            const uint32_t *corner = c + 3 * tris[3 * k + j];
            v[j] = corner[0];
            t[j] = corner[1];
            nn[j] = corner[2];
            has_t &= t[j] != IO_NONE;
            has_n &= nn[j] != IO_NONE;
        }
        if (!builder_add_triangle(ctx, v, has_n ? nn : NULL, has_t ? t : NULL, material))
            return io_error(ctx, f->shown, f->line, "out of memory");
    }
    return true;
}

static uint32_t obj_find_material(io_ctx *ctx, size_t first, const char *name) {
    for (size_t i = first; i < ctx->b.material_n; i++)
        if (strncmp(ctx->b.materials[i].name, name, sizeof ctx->b.materials[i].name - 1) == 0)
            return (uint32_t)i;
    return IO_NONE;
}

/* Reads the material library named rel (relative to the OBJ file; Windows' backslashes taken
 * for slashes, as in map_Kd). */
static bool obj_read_mtl(obj_file *f, char *rel) {
    io_ctx *ctx = f->ctx;
    char full[IO_PATH_MAX], shown[IO_PATH_MAX + 256];
    for (char *c = rel; *c; c++)
        if (*c == '\\') *c = '/';
    vfs_join(&ctx->vfs, f->path, rel, full, sizeof full);
    vfs_display(&ctx->vfs, full, shown, sizeof shown);
    io_buf mb;
    if (!vfs_read(ctx, full, &mb))
        return io_error(ctx, f->shown, f->line, "cannot open material library '%s' (%s): %s", rel, shown, ctx->why);
    bool ok = mtl_parse(ctx, full, shown, &mb);
    vfs_buf_free(&mb);
    return ok;
}

/* `mtllib a.mtl b.mtl`: one or more library names. A name with blanks (Blender and 3ds Max write
 * "mtllib my scene.mtl") is taken whole when the whole rest of the line names a file. */
static bool obj_mtllib(obj_file *f, const char *p) {
    io_ctx *ctx = f->ctx;
    char rel[IO_PATH_MAX], full[IO_PATH_MAX];
    rest_of_line(p, rel, sizeof rel);
    for (int pass = 0; pass < 2 && strpbrk(rel, " \t"); pass++) { /* the whole line, then without a comment */
        if (pass && !cut_comment(rel)) break;
        char tmp[IO_PATH_MAX];
        snprintf(tmp, sizeof tmp, "%s", rel);
        for (char *c = tmp; *c; c++)
            if (*c == '\\') *c = '/';
        vfs_join(&ctx->vfs, f->path, tmp, full, sizeof full);
        if (vfs_exists(ctx, full)) return obj_read_mtl(f, rel);
    }
    for (const char *q = p;;) {
        q = skip_blank(q);
        if (at_eol(q)) return true;
        const char *s = q;
        while (!is_delim(*q)) q++;
        snprintf(rel, sizeof rel, "%.*s", (int)(q - s), s);
        if (!obj_read_mtl(f, rel)) return false;
    }
}

/* The material a usemtl line names; IO_NONE (the default material) with a warning when no
 * library read so far defines it, as tinyobjloader does. */
static uint32_t obj_use_material(obj_file *f, size_t first, const char *name, uint32_t line) {
    io_ctx *ctx = f->ctx;
    uint32_t m = obj_find_material(ctx, first, name);
    /* not found: the names without a comment after them ("usemtl red # walls", "newmtl red # paint") */
    char cut[256], other[sizeof ctx->b.materials[0].name];
    snprintf(cut, sizeof cut, "%s", name);
    if (m == IO_NONE && cut_comment(cut)) m = obj_find_material(ctx, first, cut);
    for (size_t i = first; m == IO_NONE && i < ctx->b.material_n; i++) {
        snprintf(other, sizeof other, "%s", ctx->b.materials[i].name);
        if (cut_comment(other) && strcmp(other, cut) == 0) m = (uint32_t)i;
    }
    if (m == IO_NONE)
        io_warning(f->ctx, f->shown, line, "usemtl '%s': no material library read so far defines it; the default material is used",
                   name);
    return m;
}

/* ---- parallel parsing ------------------------------------------------------------------------- */

/* A large OBJ file is cut at line starts (every line is a statement) and the chunks are parsed on
 * the load's threads: vertices into arrays of their own, faces as their corners' indices, usemtl
 * by name. The serial pass then takes each chunk at its start, in file order: it checks that every
 * index the chunk holds is in range of what was defined before it (else it parses that chunk
 * itself and finds the error, with its message and line), resolves the material names, copies the
 * vertices in, and counts the triangles, which are triangulated and written in parallel at the end.
 * A chunk stops at a line it leaves to the serial pass (mtllib, an error, a face whose corners mix
 * with and without normals or texture coordinates). The result is the serial one, to the bit. */

#define OBJ_REL (INT64_C(1) << 40) /* corner index relative to the chunk's start: stored r - OBJ_REL */
#define OBJ_NONE INT64_MIN         /* no texture coordinate / normal */

typedef struct obj_usemtl {
    size_t face; /* the first face it applies to */
    uint32_t line; /* its line, counted from the chunk's first */
    char name[256];
    uint32_t material; /* resolved by the serial pass */
} obj_usemtl;

typedef struct obj_chunk {
    const char *start, *limit, *stop;
    uint32_t lines;                   /* lines from start to stop */
    float *pos, *nrm, *uv;            /* the chunk's v, vn, vt */
    size_t pos_n, nrm_n, uv_n, pos_cap, nrm_cap, uv_cap;
    float *col;                       /* colours of pos (white where a v has none), once one has */
    size_t col_cap;
    int64_t *corners;                 /* v, vt, vn per corner: absolute index >= 0, relative, or OBJ_NONE */
    size_t corner_n, corner_cap;
    uint32_t *faces;                  /* first corner of each face; one past the last at faces[face_n] */
    size_t face_n, face_cap, tri_n;
    obj_usemtl *mtls;
    size_t mtl_n, mtl_cap;
    int64_t need[3];                  /* v, vt, vn that must be defined before the chunk */
    bool has_t, has_n, oom;
    size_t base[3], t0;               /* where the serial pass put it */
    uint32_t first_material;          /* the material current at its start */
} obj_chunk;

typedef struct obj_par {
    obj_chunk *chunks;
    uint32_t n, next;
    const char *end;
    io_builder *b;
} obj_par;

static const char *obj_chunk_floats(const char *p, float *v, int n) {
    for (int i = 0; i < n; i++) {
        p = skip_blank(p);
        const char *q = io_parse_float(p, &v[i]);
        if (!q || !is_delim(*q)) return NULL;
        p = q;
    }
    return p;
}

static float *obj_chunk_vec(float **a, size_t *n, size_t *cap, int dim, bool *oom) {
    if (*n >= *cap && !io_reserve((void **)a, cap, *n + 1, (size_t)dim * sizeof(float))) {
        *oom = true;
        return NULL;
    }
    return *a + (size_t)dim * (*n)++;
}

/* The colour of the chunk's last vertex; the vertices before it without one are white. */
static bool obj_chunk_color(obj_chunk *c, const float rgb[3]) {
    size_t i = c->pos_n - 1, had = c->col ? c->col_cap : 0;
    if (!io_reserve((void **)&c->col, &c->col_cap, c->pos_cap > c->pos_n ? c->pos_cap : c->pos_n, 3 * sizeof(float)))
        return c->oom = true, false;
    if (had == 0)
        for (size_t k = 0; k < i; k++) c->col[3 * k] = c->col[3 * k + 1] = c->col[3 * k + 2] = 1.0f;
    memcpy(c->col + 3 * i, rgb, 3 * sizeof(float));
    return true;
}

/* One face line into the chunk, as obj_face would read it; false leaves it to the serial pass. */
static bool obj_chunk_face(obj_chunk *c, const char *p) {
    size_t first = c->corner_n;
    uint32_t n = 0;
    int has[2] = {0, 0}; /* corners with a texture coordinate, with a normal */
    const size_t counts[3] = {c->pos_n, c->uv_n, c->nrm_n};
    for (;;) {
        p = skip_blank(p);
        if (at_eol(p)) break;
        if (c->corner_n + 3 > c->corner_cap &&
            !io_reserve((void **)&c->corners, &c->corner_cap, c->corner_n + 3, sizeof(int64_t)))
            return c->oom = true, false;
        int64_t raw[3] = {0, 0, 0};
        bool present[3] = {true, false, false};
        const char *q = io_parse_int(p, &raw[0]);
        if (!q) return false;
        if (*q == '/') {
            q++;
            if (*q != '/' && !(present[1] = (q = io_parse_int(q, &raw[1])) != NULL)) return false;
            if (*q == '/' && !(present[2] = (q = io_parse_int(q + 1, &raw[2])) != NULL)) return false;
        }
        if (!is_delim(*q) && *q != '#') return false;
        int64_t *e = c->corners + c->corner_n;
        for (int k = 0; k < 3; k++) {
            if (!present[k]) {
                e[k] = OBJ_NONE;
                continue;
            }
            /* index 0 and huge ones are errors or rarities the serial pass reports */
            if (raw[k] == 0 || raw[k] > INT32_MAX || raw[k] < -INT32_MAX) return false;
            int64_t lc = (int64_t)counts[k];
            if (raw[k] > 0) { /* index raw - 1 must exist: base + lc > raw - 1 */
                e[k] = raw[k] - 1;
                if (raw[k] - lc > c->need[k]) c->need[k] = raw[k] - lc;
            } else { /* base + lc + raw >= 0 */
                e[k] = lc + raw[k] - OBJ_REL;
                if (-(lc + raw[k]) > c->need[k]) c->need[k] = -(lc + raw[k]);
            }
        }
        has[0] += e[1] != OBJ_NONE;
        has[1] += e[2] != OBJ_NONE;
        c->corner_n += 3;
        p = q;
        if (++n >= 64) return false; /* big polygons: the serial pass */
    }
    if (n < 3 || (has[0] && has[0] != (int)n) || (has[1] && has[1] != (int)n)) return false;
    if (c->face_n + 2 > c->face_cap && !io_reserve((void **)&c->faces, &c->face_cap, c->face_n + 2, sizeof(uint32_t)))
        return c->oom = true, false;
    if (first > UINT32_MAX - 3 * 64) return false;
    c->faces[c->face_n++] = (uint32_t)first;
    c->faces[c->face_n] = (uint32_t)c->corner_n;
    c->tri_n += n - 2;
    c->has_t |= has[0] != 0;
    c->has_n |= has[1] != 0;
    return true;
}

/* Reserves the chunk's arrays for the statements its lines start with (faces of three corners),
 * so that they grow without copies; a failure here is met again, and reported, when they grow. */
static void obj_chunk_presize(obj_chunk *c) {
    size_t v = 0, vn = 0, vt = 0, f = 0;
    for (const char *p = c->start; p < c->limit;) {
        const char *s = skip_blank(p);
        if (s[0] == 'v') {
            v += s[1] == ' ' || s[1] == '\t';
            vn += s[1] == 'n';
            vt += s[1] == 't';
        } else {
            f += s[0] == 'f';
        }
        const char *nl = memchr(s, '\n', (size_t)(c->limit - s));
        p = nl ? nl + 1 : c->limit;
    }
    (void)(io_reserve((void **)&c->pos, &c->pos_cap, v, 3 * sizeof(float)) &&
           io_reserve((void **)&c->nrm, &c->nrm_cap, vn, 3 * sizeof(float)) &&
           io_reserve((void **)&c->uv, &c->uv_cap, vt, 2 * sizeof(float)) &&
           io_reserve((void **)&c->faces, &c->face_cap, f + 1, sizeof(uint32_t)) &&
           io_reserve((void **)&c->corners, &c->corner_cap, 9 * f, sizeof(int64_t)));
}

static void obj_chunk_task(void *user, uint32_t index) {
    obj_par *par = user;
    obj_chunk *c = &par->chunks[index];
    c->need[0] = c->need[1] = c->need[2] = INT64_MIN;
    obj_chunk_presize(c);
    const char *p = c->start, *end = par->end;
    uint32_t line = 0;
    bool backslash = memchr(c->start, '\\', (size_t)(c->limit - c->start)) != NULL;
    for (; p < c->limit; p = next_line(p, end), line++) {
        size_t undo[5] = {c->pos_n, c->nrm_n, c->uv_n, c->corner_n, c->mtl_n};
        const char *s = skip_blank(p);
        bool ok = true, continued = false;
        if (backslash && !at_eol(s)) line_end(s, end, &continued);
        if (at_eol(s)) {
            ok = !(*s == '\0' && s < end);
        } else if (continued) {
            ok = false; /* a statement over several lines: the serial pass joins them */
        } else if (s[0] == 'v' && (s[1] == ' ' || s[1] == '\t')) {
            float *v = obj_chunk_vec(&c->pos, &c->pos_n, &c->pos_cap, 3, &c->oom);
            const char *q = v ? obj_chunk_floats(s + 1, v, 3) : NULL;
            ok = q != NULL;
            float rgb[3] = {1, 1, 1};
            bool colored = ok && obj_vertex_color(q, rgb);
            if (ok && (colored || c->col)) ok = obj_chunk_color(c, rgb);
        } else if (s[0] == 'f' && (s[1] == ' ' || s[1] == '\t')) {
            ok = obj_chunk_face(c, s + 1);
        } else if (s[0] == 'v' && s[1] == 'n' && is_delim(s[2])) {
            float *v = obj_chunk_vec(&c->nrm, &c->nrm_n, &c->nrm_cap, 3, &c->oom);
            ok = v && obj_chunk_floats(s + 2, v, 3);
        } else if (s[0] == 'v' && s[1] == 't' && is_delim(s[2])) {
            float *v = obj_chunk_vec(&c->uv, &c->uv_n, &c->uv_cap, 2, &c->oom);
            const char *q = v ? obj_chunk_floats(s + 2, v, 1) : NULL;
            ok = q != NULL;
            if (ok) {
                v[1] = 0.0f;
                if (!at_eol(skip_blank(q))) ok = obj_chunk_floats(q, v + 1, 1) != NULL;
            }
        } else if (word_is(s, "usemtl")) {
            ok = io_reserve((void **)&c->mtls, &c->mtl_cap, c->mtl_n + 1, sizeof *c->mtls);
            if (ok) {
                obj_usemtl *u = &c->mtls[c->mtl_n++];
                u->face = c->face_n;
                u->line = line;
                rest_of_line(s + 6, u->name, sizeof u->name);
            } else {
                c->oom = true;
            }
        } else {
            ok = !word_is(s, "mtllib") && obj_skippable(s);
        }
        if (!ok) { /* this line and the rest to the serial pass */
            c->pos_n = undo[0], c->nrm_n = undo[1], c->uv_n = undo[2], c->corner_n = undo[3], c->mtl_n = undo[4];
            break;
        }
    }
    c->stop = p < c->limit ? p : c->limit;
    c->lines = line;
}

static void obj_chunk_free(obj_chunk *c) {
    free(c->pos);
    free(c->nrm);
    free(c->uv);
    free(c->col);
    free(c->corners);
    free(c->faces);
    free(c->mtls);
    memset(c, 0, sizeof *c);
}

/* total, when more than size (a streamed file's first window), is the file's size: the scene's
 * arrays are then sized for the whole file from this window's counts (only address space). */
static void obj_par_start(io_ctx *ctx, obj_par *par, const char *data, size_t size, uint64_t total) {
    memset(par, 0, sizeof *par);
    uint32_t k = io_chunk_count(ctx, size);
    const char **starts = NULL;
    if (k < 2 || !(par->chunks = calloc(k, sizeof *par->chunks)) || !(starts = malloc(k * sizeof *starts))) {
        free(par->chunks);
        par->chunks = NULL;
        return;
    }
    const char *end = data + size;
    par->n = io_split_lines(data, size, k, starts);
    for (uint32_t i = 0; i < par->n; i++) par->chunks[i].start = starts[i];
    free(starts);
    for (uint32_t i = 0; i < par->n; i++) par->chunks[i].limit = i + 1 < par->n ? par->chunks[i + 1].start : end;
    par->end = end;
    par->b = &ctx->b;
    io_parallel_for(ctx->threads, par->n, obj_chunk_task, par);
    size_t pos = 0, nrm = 0, uv = 0, tri = 0;
    for (uint32_t i = 0; i < par->n; i++) {
        const obj_chunk *c = &par->chunks[i];
        pos += c->pos_n, nrm += c->nrm_n, uv += c->uv_n, tri += c->tri_n;
    }
    if (total > size) {
        double scale = (double)total / (double)size * 1.03, most = (double)(total / 6 + 16);
        pos = (size_t)fmin((double)pos * scale, most), nrm = (size_t)fmin((double)nrm * scale, most);
        uv = (size_t)fmin((double)uv * scale, most), tri = (size_t)fmin((double)tri * scale, most);
    }
    (void)(builder_reserve_vertices(ctx, pos) && builder_reserve_normals(ctx, nrm) &&
           builder_reserve_texcoords(ctx, uv) && builder_reserve_triangles(ctx, tri));
}

static void obj_par_end(obj_par *par) {
    for (uint32_t i = 0; i < par->n; i++) obj_chunk_free(&par->chunks[i]);
    free(par->chunks);
    memset(par, 0, sizeof *par);
}

/* At line start *p: takes the chunk that starts there when its indices hold; true when it did,
 * *p and f->line then past it. *material is the current material before and after. */
static bool obj_par_take(obj_file *f, obj_par *par, const char **p, uint32_t *material, size_t first_mtl, bool *ok) {
    while (par->next < par->n && par->chunks[par->next].start < *p) obj_chunk_free(&par->chunks[par->next++]);
    if (par->next >= par->n || par->chunks[par->next].start != *p) return false;
    obj_chunk *c = &par->chunks[par->next++];
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    const size_t have[3] = {b->pos_n, b->uv_n, b->nrm_n};
    bool fits = c->stop > c->start && !c->oom;
    for (int k = 0; fits && k < 3; k++) fits = c->need[k] == INT64_MIN || c->need[k] <= (int64_t)have[k];
    if (!fits) { /* the serial pass parses it, and finds the error if there is one */
        obj_chunk_free(c);
        return false;
    }
    /* Materials in file order, as the serial pass meets the usemtl lines and faces: the faces after
     * each usemtl (and before the first) use its material, the default one (made at the first
     * such face) when the name is unknown. */
    uint32_t cur = *material;
    for (size_t i = 0; i <= c->mtl_n; i++) {
        size_t from = i ? c->mtls[i - 1].face : 0, to = i < c->mtl_n ? c->mtls[i].face : c->face_n;
        uint32_t use = cur;
        if (to > from && use == IO_NONE && (use = builder_default_material(ctx)) == IO_NONE)
            return *ok = io_error(ctx, f->shown, f->line, "out of memory"), true;
        if (i) c->mtls[i - 1].material = use;
        else c->first_material = use;
        if (i < c->mtl_n) cur = obj_use_material(f, first_mtl, c->mtls[i].name, f->line + c->mtls[i].line);
    }
    *material = cur;
    if (b->pos_n + c->pos_n >= UINT32_MAX || b->nrm_n + c->nrm_n >= UINT32_MAX || b->uv_n + c->uv_n >= UINT32_MAX ||
        !builder_reserve_vertices(ctx, c->pos_n) || !builder_reserve_normals(ctx, c->nrm_n) ||
        !builder_reserve_texcoords(ctx, c->uv_n) || !builder_claim_triangles(ctx, c->tri_n, c->has_n, c->has_t))
        return *ok = io_error(ctx, f->shown, f->line, "out of memory"), true;
    /* vertices now (serial faces after the chunk may triangulate with them), triangles at the end */
    c->base[0] = b->pos_n, c->base[1] = b->uv_n, c->base[2] = b->nrm_n;
    c->t0 = b->tri_n - c->tri_n;
    if (c->col && c->pos_n && !builder_set_colors(ctx, b->pos_n, c->col, c->pos_n))
        return *ok = io_error(ctx, f->shown, f->line, "out of memory"), true;
    if (c->pos_n) memcpy(b->pos + 3 * b->pos_n, c->pos, 3 * sizeof(float) * c->pos_n);
    if (c->nrm_n) memcpy(b->nrm + 3 * b->nrm_n, c->nrm, 3 * sizeof(float) * c->nrm_n);
    if (c->uv_n) memcpy(b->uv + 2 * b->uv_n, c->uv, 2 * sizeof(float) * c->uv_n);
    b->pos_n += c->pos_n, b->nrm_n += c->nrm_n, b->uv_n += c->uv_n;
    ctx->chunks_taken++;
    *p = c->stop;
    f->line += c->lines;
    return true;
}

static inline uint32_t obj_resolve(int64_t e, size_t base) {
    if (e == OBJ_NONE) return IO_NONE;
    return (uint32_t)(e >= 0 ? e : (int64_t)base + (e + OBJ_REL));
}

static void obj_fill_task(void *user, uint32_t index) {
    obj_par *par = user;
    obj_chunk *c = &par->chunks[index];
    if (!c->faces) return; /* not taken, or no faces */
    io_builder *b = par->b;
    uint32_t material = c->first_material;
    size_t next_mtl = 0, t = c->t0;
    for (size_t fi = 0; fi < c->face_n; fi++) {
        while (next_mtl < c->mtl_n && c->mtls[next_mtl].face == fi) material = c->mtls[next_mtl++].material;
        const int64_t *e = c->corners + c->faces[fi];
        uint32_t n = (c->faces[fi + 1] - c->faces[fi]) / 3;
        uint32_t corner[3 * 64], tris[3 * 62], ring[64];
        float pts[3 * 64];
        for (uint32_t i = 0; i < n; i++)
            for (int k = 0; k < 3; k++) corner[3 * i + (uint32_t)k] = obj_resolve(e[3 * i + (uint32_t)k], c->base[k]);
        if (n == 3) {
            tris[0] = 0, tris[1] = 1, tris[2] = 2;
        } else {
            for (uint32_t i = 0; i < n; i++) memcpy(pts + 3 * i, b->pos + 3 * (size_t)corner[3 * i], 3 * sizeof(float));
            poly_triangulate(pts, n, tris, ring);
        }
        for (uint32_t k = 0; k < n - 2; k++, t++) {
            bool has_t = true, has_n = true;
            for (int j = 0; j < 3; j++) {
                const uint32_t *cj = corner + 3 * tris[3 * k + (uint32_t)j];
                b->idx[3 * t + (size_t)j] = cj[0];
                has_t &= cj[1] != IO_NONE;
                has_n &= cj[2] != IO_NONE;
            }
            for (int j = 0; j < 3; j++) {
                const uint32_t *cj = corner + 3 * tris[3 * k + (uint32_t)j];
                if (b->tidx) b->tidx[3 * t + (size_t)j] = has_t ? cj[1] : IO_NONE;
                if (b->nidx) b->nidx[3 * t + (size_t)j] = has_n ? cj[2] : IO_NONE;
            }
            b->mat[t] = material;
        }
    }
}

/* One statement at p (blanks skipped, not a comment), up to its line's end or a NUL. */
static bool obj_statement(obj_file *f, const char *p, uint32_t *material, size_t first_mtl) {
    io_ctx *ctx = f->ctx;
    io_builder *b = &ctx->b;
    bool ok = true;
    if (p[0] == 'v' && (p[1] == ' ' || p[1] == '\t')) {
        if (b->pos_n >= b->pos_cap && (b->pos_n >= UINT32_MAX || !builder_reserve_vertices(ctx, 1)))
            return io_error(ctx, f->shown, f->line, "out of memory");
        float *v = b->pos + 3 * b->pos_n;
        const char *q = p + 1;
        ok = (q = obj_float(f, q, &v[0], "v")) && (q = obj_float(f, q, &v[1], "v")) && (q = obj_float(f, q, &v[2], "v"));
        float rgb[3];
        if (ok && obj_vertex_color(q, rgb) && !builder_set_colors(ctx, b->pos_n, rgb, 1))
            return io_error(ctx, f->shown, f->line, "out of memory");
        b->pos_n++;
    } else if (p[0] == 'f' && (p[1] == ' ' || p[1] == '\t')) {
        ok = obj_face(f, p + 1, *material);
    } else if (p[0] == 'v' && p[1] == 'n' && is_delim(p[2])) {
        if (b->nrm_n >= b->nrm_cap && (b->nrm_n >= UINT32_MAX || !builder_reserve_normals(ctx, 1)))
            return io_error(ctx, f->shown, f->line, "out of memory");
        float *v = b->nrm + 3 * b->nrm_n;
        const char *q = p + 2;
        ok = (q = obj_float(f, q, &v[0], "vn")) && (q = obj_float(f, q, &v[1], "vn")) &&
             (q = obj_float(f, q, &v[2], "vn"));
        b->nrm_n++;
    } else if (p[0] == 'v' && p[1] == 't' && is_delim(p[2])) {
        if (b->uv_n >= b->uv_cap && (b->uv_n >= UINT32_MAX || !builder_reserve_texcoords(ctx, 1)))
            return io_error(ctx, f->shown, f->line, "out of memory");
        float *v = b->uv + 2 * b->uv_n;
        const char *q = p + 2;
        v[1] = 0.0f;
        ok = (q = obj_float(f, q, &v[0], "vt")) != NULL;
        if (ok && !at_eol(skip_blank(q))) ok = obj_float(f, q, &v[1], "vt") != NULL;
        b->uv_n++;
    } else if (word_is(p, "usemtl")) {
        char name[256];
        rest_of_line(p + 6, name, sizeof name);
        *material = obj_use_material(f, first_mtl, name, f->line);
    } else if (word_is(p, "mtllib")) {
        ok = obj_mtllib(f, p + 6);
    } else if (!obj_skippable(p)) {
        int len = 0;
        while (len < 24 && !is_delim(p[len])) len++;
        ok = io_error(ctx, f->shown, f->line, "unknown statement '%.*s'", len, p);
    }
    return ok;
}

/* A statement continued over lines (each ending in a backslash but the last) joined into one
 * NUL-terminated io_malloc'd line, each backslash and line break a blank; *last is its last
 * line's start, *more the lines after the first. NULL when out of memory. */
static char *obj_join(const char *p, const char *end, const char **last, uint32_t *more) {
    size_t n = 0, cap = 256;
    char *out = io_malloc(cap);
    *more = 0;
    for (;;) {
        bool continued;
        const char *e = line_end(p, end, &continued);
        size_t len = (size_t)(e - p);
        if (!io_reserve((void **)&out, &cap, n + len + 2, 1)) {
            free(out);
            return NULL;
        }
        if (!out) return NULL;
        memcpy(out + n, p, len);
        n += len;
        if (n && out[n - 1] == '\r') n--;
        *last = p;
        if (!continued || e >= end) break;
        out[n - 1] = ' '; /* the backslash */
        out[n++] = ' ';   /* the line break */
        p = e + 1;
        ++*more;
    }
    out[n] = '\0';
    return out;
}

/* Parses the lines [p, end): a whole file, or a window of one streamed (whole lines, the line
 * numbers going on from the window before). *material is the current material before and after;
 * total, when not 0, the file's size, for presizing the scene's arrays from this first window.
 * A statement continued over lines by backslashes is parsed here whole; the chunks leave it to
 * this pass (a streamed file's statement continued past its window is not joined). */
static bool obj_lines(obj_file *f, const char *p, const char *end, uint32_t *material, size_t first_mtl, uint64_t total) {
    io_ctx *ctx = f->ctx;
    bool ok = true;
    bool backslash = memchr(p, '\\', (size_t)(end - p)) != NULL; /* else no line is continued */
    obj_par par;
    obj_par_start(ctx, &par, p, (size_t)(end - p), total);
    for (; ok && p < end; p = next_line(p, end), f->line++) {
        while (ok && p < end && par.n && obj_par_take(f, &par, &p, material, first_mtl, &ok)) {}
        if (!ok || p >= end) break;
        p = skip_blank(p);
        if (at_eol(p)) {
            if (*p == '\0' && p < end) ok = io_error(ctx, f->shown, f->line, "binary data in a text file");
            continue;
        }
        bool continued = false;
        if (backslash) line_end(p, end, &continued);
        if (!continued) {
            ok = obj_statement(f, p, material, first_mtl);
            continue;
        }
        const char *last;
        uint32_t more;
        char *joined = obj_join(p, end, &last, &more);
        if (!joined) {
            ok = io_error(ctx, f->shown, f->line, "out of memory");
            break;
        }
        const char *js = skip_blank(joined);
        if (!at_eol(js)) ok = obj_statement(f, js, material, first_mtl); /* errors name the statement's first line */
        free(joined);
        p = last;
        f->line += more;
    }
    if (ok && par.n) io_parallel_for(ctx->threads, par.n, obj_fill_task, &par);
    obj_par_end(&par);
    return ok;
}

/* obj_load for a gzip'd file on disk read as a stream (io_stream): window after window of whole
 * lines, inflated on a thread of its own while the window before is parsed; the same result and
 * errors (a corrupt file's first, as a whole read reports it). */
static bool obj_stream(obj_file *f, io_stream *s, uint32_t *material, size_t first_mtl) {
    io_ctx *ctx = f->ctx;
    bool ok = true, bad = false;
    for (;;) {
        io_text t;
        if (!io_stream_next(s, ctx, &t)) {
            bad = true;
            break;
        }
        const char *from = ctx->blocks ? t.data : io_skip_bom(t.data, t.data + t.size);
        ok = obj_lines(f, from, t.data + t.size, material, first_mtl, ctx->blocks++ ? 0 : io_stream_size_hint(s));
        io_stream_release(s);
        if (!ok || t.last) break;
    }
    if (!bad && !ok) bad = !io_stream_drain(s, ctx);
    if (bad) {
        ctx->failed = false;
        ok = io_error(ctx, f->shown, 0, "cannot open: %s", ctx->why);
    }
    ctx->bytes += io_stream_total(s);
    io_stream_close(s);
    return ok;
}

bool obj_load(io_ctx *ctx, const char *path) {
    obj_file f = {.ctx = ctx, .path = path, .line = 1};
    vfs_display(&ctx->vfs, path, f.shown, sizeof f.shown);
    uint32_t material = IO_NONE;
    size_t first_mtl = ctx->b.material_n;
    /* a large gzip'd file on disk is streamed (archive entries are in memory already) */
    if (!ctx->vfs.archive && ctx->stream >= 0 && (ctx->stream > 0 || ctx->threads > 1)) {
        io_stream *s = io_stream_open(ctx, path, ctx->stream > 0 ? 0 : IO_STREAM_MIN_TEXT, ctx->stream_block, NULL);
        if (s) return obj_stream(&f, s, &material, first_mtl);
    }
    io_buf buf;
    if (!vfs_read(ctx, path, &buf)) return io_error(ctx, f.shown, 0, "cannot open: %s", ctx->why);
    ctx->bytes += buf.size;
    bool ok = obj_lines(&f, io_skip_bom(buf.data, buf.data + buf.size), buf.data + buf.size, &material, first_mtl, 0);
    vfs_buf_free(&buf);
    return ok;
}
