// rp-test: labels=io timeout=300
/* Allocation failures in the loaders (issue 23): the loaders' allocation hook (io_set_alloc_hook)
 * refuses the k-th allocation of a load, for every k up to the number the load takes, in two modes
 * (the k-th alone; the k-th and every later one), for each format: OBJ+MTL with PPM, PNG and JPEG
 * textures, OBJ gzip'd, PLY ascii and binary (both byte orders), NFF with an include, AFF with
 * nested includes and a texture, tar and tar.gz archives, glTF through assimp (our allocations;
 * assimp's own are C++ new and not refused), and the HDR and PFM readers. Inputs are the fuzzers'
 * seeds (tests/fuzz/corpus), written out as files and loaded from disk.
 *
 * Each refused load must fail with an error that names the file and says "out of memory" (or, where
 * the refusal hit an optional buffer with a fallback, succeed with exactly the scene of an
 * unrefused load), give back every byte (glibc's count of bytes in use here; LeakSanitizer in the
 * ASan build), and leave the process able to load: the next, unrefused load gives the same scene. */
#include <malloc.h>
#include <unistd.h>
#include <stdatomic.h>
#include <sys/stat.h>
#include <zlib.h>

#include "io/io_internal.h"
#include "raypack_io.h"
#include "rp_test.h"

#if defined(__SANITIZE_ADDRESS__)
#define LSAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define LSAN 1
#endif
#endif
#if LSAN
#include <sanitizer/lsan_interface.h>
#endif

static atomic_long count, fail_at, refused;
static bool only; /* refuse the k-th alone, else the k-th and all later ones */

static bool hook(void *user, size_t size) {
    (void)user, (void)size;
    long k = atomic_fetch_add(&count, 1) + 1, at = atomic_load(&fail_at);
    if (at > 0 && (only ? k == at : k >= at)) {
        atomic_fetch_add(&refused, 1);
        return false;
    }
    return true;
}

static void arm(long k) {
    atomic_store(&count, 0);
    atomic_store(&refused, 0);
    atomic_store(&fail_at, k);
}

/* Bytes malloc holds for the program (glibc); 0 under ASan, whose LeakSanitizer checks instead. */
static size_t bytes_in_use(void) {
#if LSAN
    return 0;
#else
    return mallinfo2().uordblks;
#endif
}

static uint64_t fnv(uint64_t h, const void *p, size_t n) {
    const unsigned char *b = p;
    for (size_t i = 0; i < n; i++) h = (h ^ b[i]) * 1099511628211ull;
    return h;
}

/* Fingerprint of a loaded scene: counts and every array. */
static uint64_t scene_hash(const rp_scene_data *s) {
    uint64_t h = 1469598103934665603ull;
    size_t counts[] = {s->vertex_count, s->normal_count, s->texcoord_count, s->triangle_count, s->sphere_count,
                       s->cone_count, s->material_count, s->texture_count, s->light_count};
    h = fnv(h, counts, sizeof counts);
    h = fnv(h, s->positions, 3 * s->vertex_count * sizeof(float));
    if (s->normals) h = fnv(h, s->normals, 3 * s->normal_count * sizeof(float));
    if (s->texcoords) h = fnv(h, s->texcoords, 2 * s->texcoord_count * sizeof(float));
    h = fnv(h, s->indices, 3 * s->triangle_count * sizeof(uint32_t));
    if (s->normal_indices) h = fnv(h, s->normal_indices, 3 * s->triangle_count * sizeof(uint32_t));
    if (s->texcoord_indices) h = fnv(h, s->texcoord_indices, 3 * s->triangle_count * sizeof(uint32_t));
    h = fnv(h, s->tri_materials, s->triangle_count * sizeof(uint32_t));
    for (size_t i = 0; i < s->sphere_count; i++) h = fnv(h, s->spheres[i].center, 4 * sizeof(float));
    for (size_t i = 0; i < s->cone_count; i++) h = fnv(h, s->cones[i].base, 8 * sizeof(float));
    for (size_t i = 0; i < s->material_count; i++) {
        h = fnv(h, s->materials[i].kd, sizeof s->materials[i].kd);
        h = fnv(h, &s->materials[i].map_kd, sizeof(int32_t));
    }
    for (size_t i = 0; i < s->texture_count; i++) {
        const rp_texture_data *t = &s->textures[i];
        h = fnv(h, &t->width, sizeof t->width);
        h = fnv(h, &t->height, sizeof t->height);
        h = fnv(h, t->rgb, 3 * (size_t)t->width * (size_t)t->height);
    }
    return h;
}

typedef enum kind { LOAD_SCENE, READ_HDR, READ_PFM } kind;

/* Loads (or reads) the case once; *hash its result, false when it failed (err says why). */
static bool run(kind k, const char *path, uint64_t *hash, char *err, size_t err_size) {
    if (k == LOAD_SCENE) {
        rp_scene_data s;
        if (!rp_scene_data_load(path, &s, err, err_size)) return false;
        *hash = scene_hash(&s);
        rp_scene_data_free(&s);
        return true;
    }
    int w = 0, h = 0, c = 3;
    float *px = k == READ_HDR ? rp_image_read_hdr(path, &w, &h, err, err_size)
                              : rp_image_read_pfm(path, &w, &h, &c, err, err_size);
    if (!px) return false;
    *hash = fnv(fnv(1469598103934665603ull, &w, sizeof w), px, (size_t)w * (size_t)h * (size_t)c * sizeof(float));
    free(px);
    return true;
}

static int cases_run;
static char tmp[512]; /* the folder the inputs are written to */

/* Every k, both modes, for one file. */
static void sweep(kind k, const char *path, const char *label) {
    char err[1024];
    uint64_t expect = 0, got = 0;
    arm(0);
    if (!run(k, path, &expect, err, sizeof err)) {
        CHECKF(false, "%s does not load: %s", path, err);
        return;
    }
    long total = atomic_load(&count);
    CHECKF(total > 0, "%s: the load made no allocation through the hook", path);
    int failures = 0, fallbacks = 0;
    for (int mode = 0; mode < 2; mode++) {
        only = mode == 1;
        for (long at = 1; at <= total; at++) {
            size_t before = bytes_in_use();
            arm(at);
            err[0] = '\0';
            bool ok = run(k, path, &got, err, sizeof err);
            long n_refused = atomic_load(&refused);
            arm(0);
            size_t after = bytes_in_use();
            CHECKF(n_refused > 0, "%s: allocation %ld of %ld was never asked for", path, at, total);
            if (ok) { /* a refusal absorbed by a fallback (libdeflate -> zlib, ...): same scene */
                CHECKF(got == expect, "%s, k=%ld (%s): loaded, but not the same scene", path, at,
                       only ? "alone" : "and later");
                fallbacks++;
            } else {
                /* the file the refusal hit: the scene, an include, an archive entry */
                CHECKF(strstr(err, ": error: ") && strstr(err, "out of memory") && (strstr(err, tmp) || strstr(err, ".tar")),
                       "%s, k=%ld (%s): error does not name the file and say out of memory: %s", path, at,
                       only ? "alone" : "and later", err);
                failures++;
            }
            CHECKF(after == before, "%s, k=%ld (%s): %zu bytes not given back", path, at, only ? "alone" : "and later",
                   after - before);
            /* the next load works and gives the same scene */
            bool again = run(k, path, &got, err, sizeof err);
            CHECKF(again && got == expect, "%s, k=%ld: the load after a refused one failed: %s", path, at,
                   again ? "another scene" : err);
        }
    }
#if LSAN
    CHECKF(__lsan_do_recoverable_leak_check() == 0, "%s: LeakSanitizer found leaks", path);
#endif
    printf("%-24s %4ld allocations; %d refused loads failed cleanly, %d fell back to the same scene\n", label, total,
           failures, fallbacks);
    cases_run++;
}

/* ---- inputs: the fuzzers' seeds as files ------------------------------------------------------- */

static void write_file(const char *name, const void *data, size_t len) {
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", tmp, name);
    FILE *f = fopen(path, "wb");
    CHECKF(f && fwrite(data, 1, len, f) == len, "cannot write %s", path);
    if (f) fclose(f);
}

static char *read_seed(const char *rel, size_t *size) {
    const char *src = getenv("RP_SOURCE_DIR");
    char path[1024];
    snprintf(path, sizeof path, "%s/tests/fuzz/corpus/%s", src ? src : "..", rel);
    FILE *f = fopen(path, "rb");
    if (!f) {
        CHECKF(false, "seed %s not found", path);
        return NULL;
    }
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *d = malloc((size_t)n + 1);
    if (d && fread(d, 1, (size_t)n, f) != (size_t)n) n = 0;
    fclose(f);
    *size = (size_t)n;
    return d;
}

/* Writes a seed's pieces (split at "\n%%\n", as the fuzz harnesses do) as the files names[]. */
static void write_seed(const char *rel, const char *const *names, int n_names) {
    size_t size;
    char *d = read_seed(rel, &size);
    if (!d) return;
    const char *p = d, *end = d + size;
    for (int i = 0; i < n_names; i++) {
        const char *cut = NULL;
        if (i + 1 < n_names)
            for (const char *q = p; q + 4 <= end; q++)
                if (memcmp(q, "\n%%\n", 4) == 0) {
                    cut = q;
                    break;
                }
        const char *stop = cut ? cut + 1 : end;
        write_file(names[i], p, (size_t)(stop - p));
        if (!cut) break;
        p = cut + 4;
    }
    free(d);
}

static void sweep_file(kind k, const char *name, const char *label) {
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", tmp, name);
    sweep(k, path, label ? label : name);
}

/* A glTF triangle with an embedded buffer and a PNG base colour texture (t.png). */
static const char gltf[] =
    "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],"
    "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1},\"material\":0}]}],"
    "\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorTexture\":{\"index\":0}}}],"
    "\"textures\":[{\"source\":0}],\"images\":[{\"uri\":\"t.png\"}],"
    "\"buffers\":[{\"byteLength\":60,\"uri\":\"data:application/octet-stream;base64,"
    "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAIA/\"}],"
    "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":36},{\"buffer\":0,\"byteOffset\":36,\"byteLength\":24}],"
    "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\",\"min\":[0,0,0],\"max\":[1,1,0]},"
    "{\"bufferView\":1,\"componentType\":5126,\"count\":3,\"type\":\"VEC2\"}]}\n";

/* Blocks from 1 MiB start on a 2 MiB boundary (so all of a block can be huge pages), are usable to
 * their size, grow with their contents kept, and go back with free(); small ones are malloc's. */
static void test_large_blocks(void) {
    const uintptr_t huge = (uintptr_t)2 << 20;
    const size_t sizes[] = {(size_t)1 << 20, ((size_t)3 << 20) + 5, 7607064};
    for (size_t i = 0; i < sizeof sizes / sizeof sizes[0]; i++) {
        size_t n = sizes[i];
        unsigned char *a = io_malloc(n), *b = io_realloc(NULL, n);
        CHECKF(a && b && ((uintptr_t)a & (huge - 1)) == 0 && ((uintptr_t)b & (huge - 1)) == 0,
               "%zu bytes: %p %p", n, (void *)a, (void *)b);
        if (!a || !b) continue;
        memset(a, 0xA5, n);
        memset(b, 0x5A, n);
        unsigned char *c = io_realloc(b, 2 * n);
        CHECK(c != NULL);
        if (c) {
            b = c;
            CHECK(b[0] == 0x5A && b[n - 1] == 0x5A && a[n - 1] == 0xA5);
            memset(b + n, 1, n);
        }
        free(a);
        free(b);
    }
    char *small = io_malloc(100);
    CHECK(small != NULL);
    free(small);
}

int main(int argc, char **argv) {
    (void)argc;
    (void)argv;
#if !LSAN
    /* glibc counts blocks parked in its per-thread cache as in use: without the cache, the bytes in
     * use before and after a load are equal exactly when it gave everything back */
    const char *tun = getenv("GLIBC_TUNABLES");
    if (!tun || !strstr(tun, "glibc.malloc.tcache_count=0")) {
        char env[1024];
        snprintf(env, sizeof env, "%s%sglibc.malloc.tcache_count=0", tun ? tun : "", tun && *tun ? ":" : "");
        setenv("GLIBC_TUNABLES", env, 1);
        execv("/proc/self/exe", argv);
        perror("execv /proc/self/exe"); /* carry on: the byte counts may then be off by cached blocks */
    }
#endif
    const char *t = getenv("RP_TEST_TMP");
    snprintf(tmp, sizeof tmp, "%s", t ? t : "tmp_test_alloc_fail_load");
    mkdir(tmp, 0755);
    test_large_blocks();
    io_set_alloc_hook(hook, NULL);

    static const char *const obj_names[] = {"s.obj", "m.mtl", "t.ppm"};
    write_seed("obj/mtl_tex.obj", obj_names, 3);
    sweep_file(LOAD_SCENE, "s.obj", "OBJ+MTL+PPM");
    /* the same OBJ gzip'd (libdeflate whole, zlib as its fallback) */
    {
        size_t size;
        char path[1024];
        snprintf(path, sizeof path, "%s/s.obj", tmp);
        FILE *f = fopen(path, "rb");
        char buf[4096];
        size = f ? fread(buf, 1, sizeof buf, f) : 0;
        if (f) fclose(f);
        snprintf(path, sizeof path, "%s/z.obj.gz", tmp);
        gzFile gz = gzopen(path, "wb");
        CHECK(gz && gzwrite(gz, buf, (unsigned)size) == (int)size);
        if (gz) gzclose(gz);
        sweep_file(LOAD_SCENE, "z.obj.gz", NULL);
    }
    static const char *const tex_names[] = {"x.obj", "xm.mtl", "t.png"};
    static const char *const textures[] = {"texture/c.png", "texture/d.jpg", "texture/a.ppm"};
    for (int i = 0; i < 3; i++) {
        static const char obj[] = "mtllib xm.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                  "f 1/1 2/2 3/3\n";
        static const char mtl[] = "newmtl a\nKd 1 1 1\nmap_Kd t.png\n";
        write_file(tex_names[0], obj, sizeof obj - 1);
        write_file(tex_names[1], mtl, sizeof mtl - 1);
        write_seed(textures[i], tex_names + 2, 1);
        sweep_file(LOAD_SCENE, "x.obj", textures[i]);
    }
    static const char *const plys[] = {"ply/ascii.ply", "ply/binary_le.ply", "ply/binary_be.ply"};
    static const char *const ply_name[] = {"s.ply"};
    for (int i = 0; i < 3; i++) {
        write_seed(plys[i], ply_name, 1);
        sweep_file(LOAD_SCENE, "s.ply", plys[i]);
    }
    static const char *const nff_names[] = {"s.nff", "b.nff"};
    write_seed("nff/scene.nff", nff_names, 2);
    sweep_file(LOAD_SCENE, "s.nff", NULL);
    static const char *const aff_names[] = {"s.aff", "b.aff", "c.aff", "t.ppm"};
    write_seed("aff/includes.aff", aff_names, 4);
    sweep_file(LOAD_SCENE, "s.aff", NULL);
    static const char *const tars[][2] = {{"tar/aff.tar.gz", "a.tar.gz"}, {"tar/obj.tar.gz", "o.tar.gz"},
                                          {"tar/plain.tar", "p.tar"}};
    for (int i = 0; i < 3; i++) {
        write_seed(tars[i][0], &tars[i][1], 1);
        sweep_file(LOAD_SCENE, tars[i][1], NULL);
    }
    /* glTF: only where this build reads it (assimp found) */
    write_file("g.gltf", gltf, sizeof gltf - 1);
    write_seed("texture/c.png", tex_names + 2, 1);
    {
        char path[1024], err[512];
        snprintf(path, sizeof path, "%s/g.gltf", tmp);
        rp_scene_data s;
        if (rp_scene_data_load(path, &s, err, sizeof err)) {
            CHECK(s.triangle_count == 1 && s.texture_count == 1);
            rp_scene_data_free(&s);
            sweep_file(LOAD_SCENE, "g.gltf", NULL);
        } else {
            CHECKF(strstr(err, "without assimp") != NULL, "the glTF triangle does not load: %s", err);
            printf("g.gltf: skipped (%s)\n", err);
        }
    }
    /* environment maps and float images */
    float px[4 * 3 * 3];
    for (int i = 0; i < 36; i++) px[i] = 0.25f * (float)(i % 7);
    char path[1024], err[512];
    snprintf(path, sizeof path, "%s/e.hdr", tmp);
    CHECKF(rp_image_write(path, 4, 3, 3, px, err, sizeof err), "%s", err);
    sweep_file(READ_HDR, "e.hdr", NULL);
    snprintf(path, sizeof path, "%s/e.pfm", tmp);
    CHECKF(rp_image_write(path, 4, 3, 3, px, err, sizeof err), "%s", err);
    sweep_file(READ_PFM, "e.pfm", NULL);

    io_set_alloc_hook(NULL, NULL);
    CHECK(cases_run >= 16);
    return RP_TEST_END();
}
