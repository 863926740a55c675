/* Volumes: the OpenVDB loader on the shared cloud (voxel count, box, transform) and on missing,
 * non-VDB and truncated files; the homogeneous medium's transmittance by ratio tracking, delta
 * tracking and ray marching against exp(-sigma_t d), through the brick DDA (one brick of larger
 * majorant on the way); the volumetric furnace (an albedo-1 medium under a uniform environment of
 * radiance 1 looks like radiance 1, and so does a white sphere inside it); and the cloud rendered
 * by the path tracer (not black, not uniform, the same on 1 and 2 threads) and by the other
 * integrators (not black). */
#include "../src/io/io_volume.h"
#include "../src/render/medium.h"
#include "rp_test.h"

#include <math.h>
#include <sys/stat.h>

#define CLOUD "volume_wdas_cloud/wdas_cloud_sixteenth.vdb"

static float *render(rp_render_scene *s, const rp_render_desc *d) {
    float *px = malloc((size_t)d->width * (size_t)d->height * 3 * sizeof(float));
    if (!rp_render(s, d, px, NULL)) {
        free(px);
        return NULL;
    }
    return px;
}

static double mean_of(const float *px, int n) {
    double s = 0.0;
    for (int i = 0; i < n; i++) s += px[i];
    return s / n;
}

static void write_bytes(const char *path, const void *data, size_t n) {
    FILE *f = fopen(path, "wb");
    if (!f) return;
    fwrite(data, 1, n, f);
    fclose(f);
}

/* A file that does not load: false, and the message names the file and says why (`why`). */
static void check_bad(const char *path, const char *grid, const char *why) {
    rp_scene_data d;
    char err[512] = "";
    rp_scene_load_desc ld = {.threads = 1, .volume_grid = grid};
    bool ok = rp_scene_data_load_ex(path, &ld, &d, err, sizeof err);
    CHECKF(!ok, "%s loaded", path);
    if (ok) rp_scene_data_free(&d);
    CHECKF(strstr(err, path) != NULL, "the message names the file: '%s'", err);
    CHECKF(strstr(err, why) != NULL, "the message says '%s': '%s'", why, err);
}

static void test_load(void) {
    char buf[1024];
    const char *path = rp_test_scene(CLOUD, buf, sizeof buf);
    CHECK(path != NULL);
    if (!path) return;
    rp_scene_data d;
    char err[512] = "";
    CHECKF(rp_scene_data_load(path, &d, err, sizeof err), "%s", err);
    const rp_volume_data *v = d.volume;
    CHECK(v != NULL);
    CHECK(d.triangle_count == 0 && d.sphere_count == 0);
    if (!v) return;
    /* what OpenVDB reports of the grid: 415,642 active voxels from (-66,-21,-90) to (59,64,63),
     * a uniform scale of 10/3 */
    CHECKF(v->active_voxels == 415642u, "active voxels %llu", (unsigned long long)v->active_voxels);
    CHECK(strcmp(v->grid_name, "density") == 0);
    CHECK(v->active_min[0] == -66 && v->active_min[1] == -21 && v->active_min[2] == -90);
    CHECK(v->active_max[0] == 59 && v->active_max[1] == 64 && v->active_max[2] == 63);
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 4; c++)
            CHECK(fabsf(v->index_to_world[4 * r + c] - (r == c ? 10.0f / 3.0f : 0.0f)) < 1e-4f);
    /* sparse: the box's bricks, of which only some are stored */
    size_t cells = (size_t)v->dims[0] * v->dims[1] * v->dims[2];
    CHECK(v->dims[0] == 16 && v->dims[1] == 11 && v->dims[2] == 20);
    CHECKF(v->brick_count > 0 && v->brick_count < cells, "%u bricks of %zu", v->brick_count, cells);
    printf("cloud: %llu active voxels, %u of %zu bricks stored\n", (unsigned long long)v->active_voxels, v->brick_count,
           cells);
    size_t nonzero = 0, stored = 0;
    for (size_t i = 0; i < cells; i++) stored += v->brick_slot[i] != RP_VOLUME_EMPTY;
    for (size_t i = 0; i < (size_t)v->brick_count * 512; i++) nonzero += v->density[i] > 0.0f;
    CHECK(stored == v->brick_count);
    CHECKF(nonzero > 300000 && nonzero <= 415642u, "%zu voxels above 0", nonzero);
    CHECKF(v->max_density > 0.5f && v->max_density <= 1.5f, "max density %g", v->max_density);
    /* the render scene's medium spans the widened box in the world */
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    rp_render_scene *s = rp_render_scene_new(dev, &d, NULL, err, sizeof err);
    CHECKF(s != NULL, "%s", err);
    /* trilinear density at world points against OpenVDB's own (tools::BoxSampler::wsSample) */
    static const float ref[][4] = {
        {-143.8792f, -27.0214f, 12.9467f, 0.812875f}, {40.4712f, 133.8053f, -116.2615f, 0.513955f},
        {-1.2332f, 68.7028f, 28.8300f, 0.5f},          {85.0351f, -22.8262f, 73.1404f, 0.736978f},
        {139.7428f, -16.7398f, 59.8821f, 0.099863f},   {-11.9118f, 41.3670f, 137.8564f, 0.0f},
        {-103.4089f, -14.0215f, 105.8058f, 0.161827f}, {-56.5312f, -28.7273f, -11.1999f, 0.745404f}};
    for (size_t i = 0; s && i < sizeof ref / sizeof ref[0]; i++) {
        float got = medium_sigma_t(s->medium, v3_make(ref[i][0], ref[i][1], ref[i][2]));
        CHECKF(fabsf(got - ref[i][3]) < 5e-5f, "density at (%g, %g, %g): %.6f, OpenVDB's %.6f", ref[i][0], ref[i][1],
               ref[i][2], got, ref[i][3]);
    }
    rp_bounds b;
    CHECK(s && rp_render_scene_medium(s, &b));
    if (s) {
        float h = 10.0f / 3.0f;
        CHECKF(fabsf(b.lower_x + 67 * h) < 1e-2f && fabsf(b.upper_x - 60 * h) < 1e-2f, "x %g %g", b.lower_x, b.upper_x);
        CHECKF(fabsf(b.lower_y + 22 * h) < 1e-2f && fabsf(b.upper_y - 65 * h) < 1e-2f, "y %g %g", b.lower_y, b.upper_y);
        CHECKF(fabsf(b.lower_z + 91 * h) < 1e-2f && fabsf(b.upper_z - 64 * h) < 1e-2f, "z %g %g", b.lower_z, b.upper_z);
        /* the default camera frames it: its look point is the box's centre */
        rp_camera cam = rp_render_scene_default_camera(s);
        CHECK(fabsf(cam.pinhole.look[0] - 0.5f * (b.lower_x + b.upper_x)) < 1e-2f);
        CHECK(fabsf(cam.pinhole.look[2] - 0.5f * (b.lower_z + b.upper_z)) < 1e-2f);
    }
    rp_render_scene_release(s);
    rp_device_release(dev);

    /* broken files */
    const char *t = getenv("RP_TEST_TMP");
    char tmp[900], bad[1024];
    snprintf(tmp, sizeof tmp, "%s", t ? t : "tmp_test_volume");
    mkdir(tmp, 0755);
    snprintf(bad, sizeof bad, "%s/missing.vdb", tmp);
    remove(bad);
    check_bad(bad, NULL, "cannot open");
    snprintf(bad, sizeof bad, "%s/text.vdb", tmp);
    write_bytes(bad, "this is not an OpenVDB file\n", 28);
    check_bad(bad, NULL, "not an OpenVDB file");
    snprintf(bad, sizeof bad, "%s/empty.vdb", tmp);
    write_bytes(bad, "", 0);
    check_bad(bad, NULL, "not an OpenVDB file");
    FILE *f = fopen(path, "rb");
    static char head[1 << 16];
    size_t n = f ? fread(head, 1, sizeof head, f) : 0;
    if (f) fclose(f);
    CHECK(n == sizeof head);
    for (size_t cut = 16; cut <= n; cut *= 8) { /* in the header, the grid's descriptor, its tree */
        snprintf(bad, sizeof bad, "%s/cut%zu.vdb", tmp, cut);
        write_bytes(bad, head, cut);
        check_bad(bad, NULL, "truncated");
    }
    /* whole files whose declared lengths are absurd: refused from the lengths, before OpenVDB makes a
     * string of 4 GiB (it took minutes and gigabytes to find such a file too short) */
    static char whole[1 << 21];
    f = fopen(path, "rb");
    size_t size = f ? fread(whole, 1, sizeof whole, f) : 0;
    if (f) fclose(f);
    CHECK(size > 4096 && size < sizeof whole);
    uint32_t len;
    size_t at = 8 + 4 + 8 + 1 + 36 + 4; /* header, UUID, the file metadata's count: its first name */
    for (int k = 0; k < 2 && size > 4096; k++) {
        memcpy(&len, whole + at, 4);
        at += 4 + len; /* past the name, then the type */
    }
    if (size > 4096 && at + 4 < size) {
        uint32_t huge = 0xFFFFFFF0u, keep;
        memcpy(&keep, whole + at, 4);
        memcpy(whole + at, &huge, 4);
        snprintf(bad, sizeof bad, "%s/filemeta.vdb", tmp);
        write_bytes(bad, whole, size);
        check_bad(bad, NULL, "the file's metadata, entry 1 (its value) declares 4294967280 bytes");
        memcpy(whole + at, &keep, 4);
    }
    bool found = false;
    for (size_t i = 100; i + 9 < size && i < 4096 && !found; i++) /* the grid's first metadata name, "class" */
        if (memcmp(whole + i, "\x05\0\0\0class", 9) == 0) {
            found = true;
            uint32_t huge = 0x7FFFFFFFu;
            memcpy(whole + i, &huge, 4);
            snprintf(bad, sizeof bad, "%s/gridmeta.vdb", tmp);
            write_bytes(bad, whole, size);
            check_bad(bad, NULL, "grid 1's metadata, entry 1 (its name) declares 2147483647 bytes");
        }
    CHECK(found);
    check_bad(path, "temperature", "no float grid named 'temperature'");
    rp_scene_data_free(&d);
}

/* A homogeneous cube of 32^3 voxels of density 0.5, voxels 0.1 apart from (1, 2, 3), in a render
 * scene whose density scale makes sigma_t = 0.35 per world unit inside. Voxels (x, 0, 0) hold 2:
 * their bricks' majorants are 4 times the density that rays at y, z >= 1 meet there. */
static const float SIGMA = 0.35f, VOXEL = 0.1f;
static rp_render_scene *homogeneous(rp_device *dev, rp_scene_data *d, rp_medium_desc md) {
    memset(d, 0, sizeof *d);
    rp_volume_data *v = calloc(1, sizeof *v);
    const int32_t lo[3] = {0, 0, 0}, hi[3] = {31, 31, 31};
    const float xfm[12] = {VOXEL, 0, 0, 1, 0, VOXEL, 0, 2, 0, 0, VOXEL, 3};
    bool ok = io_volume_begin(v, lo, hi, xfm);
    for (int z = 0; ok && z < 32; z++)
        for (int y = 0; y < 32; y++)
            for (int x = 0; x < 32; x++) ok = ok && io_volume_set(v, x, y, z, y == 0 && z == 0 ? 2.0f : 0.5f);
    ok = ok && io_volume_finish(v);
    CHECK(ok);
    d->volume = v;
    char err[256] = "";
    md.density_scale = SIGMA / 0.5f;
    rp_render_scene *s = rp_render_scene_new(dev, d, &(rp_render_scene_desc){.medium = md, .environment_scale = {1, 1, 1}},
                                             err, sizeof err);
    CHECKF(s != NULL, "%s", err);
    return s;
}

static v3 world(v3 idx) { return v3_make(1 + VOXEL * idx.x, 2 + VOXEL * idx.y, 3 + VOXEL * idx.z); }

static void test_transmittance(void) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 1});
    rp_scene_data d;
    rp_render_scene *s = homogeneous(dev, &d, (rp_medium_desc){0});
    if (!s) return;
    const render_medium *m = s->medium;
    CHECK(fabsf(medium_sigma_t(m, world(v3_make(10.3f, 20.7f, 5.5f))) - SIGMA) < 1e-5f);
    CHECK(medium_sigma_t(m, world(v3_make(40, 5, 5))) == 0.0f);
    int n = rp_test_sanitized() ? 4000 : 40000;
    /* inside, along x through the bricks of majorant 4 sigma; diagonally across bricks on every
     * axis; from outside through the whole cube (the trilinear ramps at its faces add a voxel) */
    struct {
        v3 a, b;
        float tau;
        bool outside;
    } rays[3] = {
        {v3_make(1.5f, 0.6f, 0.6f), v3_make(30.5f, 0.6f, 0.6f), 0, false},
        {v3_make(1.5f, 1.5f, 1.5f), v3_make(30.0f, 29.0f, 28.5f), 0, false},
        {v3_make(-20.0f, 10.5f, 12.25f), v3_make(60.0f, 10.5f, 12.25f), SIGMA * 32 * VOXEL, true},
    };
    /* the first ray meets voxels (x, 0, 0) of density 2: y = z = 0.6 reads them with weight 0.16 */
    rays[0].tau = SIGMA * 29 * VOXEL * (1.0f + 3.0f * 0.4f * 0.4f);
    rays[1].tau = SIGMA * VOXEL * v3_length(v3_sub(rays[1].b, rays[1].a));
    for (int r = 0; r < 3; r++) {
        v3 a = world(rays[r].a), b = world(rays[r].b);
        float dist = v3_length(v3_sub(b, a));
        v3 dir = v3_scale(v3_sub(b, a), 1.0f / dist);
        double want = exp(-(double)rays[r].tau), ratio = 0.0, escaped = 0.0;
        medium_rng rng = medium_rng_seed(1, 2, (uint32_t)r);
        for (int i = 0; i < n; i++) {
            ratio += medium_transmittance(m, a, dir, dist, &rng);
            float t;
            escaped += !medium_sample_collision(m, a, dir, dist, &rng, &t);
        }
        ratio /= n;
        escaped /= n;
        printf("ray %d: exp(-tau) %.4f, ratio tracking %.4f, delta tracking %.4f (%d estimates)\n", r, want, ratio,
               escaped, n);
        double tol = 4.0 * sqrt(want * (1.0 - want) / n) + 1e-3; /* four standard deviations of a coin */
        CHECKF(fabs(ratio - want) < tol, "ray %d: ratio tracking %.4f, exp(-tau) %.4f (tol %.4f)", r, ratio, want, tol);
        CHECKF(fabs(escaped - want) < tol, "ray %d: delta tracking %.4f, exp(-tau) %.4f (tol %.4f)", r, escaped, want, tol);
        float march = medium_transmittance_march(m, a, dir, dist);
        CHECKF(fabs(march - want) < 2e-3 * want + 1e-4, "ray %d: ray marching %.5f, exp(-tau) %.5f", r, march, want);
        /* a ray that misses the cube, and one of length 0 */
        CHECK(medium_transmittance(m, world(v3_make(-5, -5, -5)), v3_make(-1, 0, 0), INFINITY, &rng) == 1.0f);
        CHECK(medium_transmittance(m, a, dir, 0.0f, &rng) == 1.0f);
    }
    /* the phase function integrates to 1 and its sampler follows it (mean cosine = g) */
    for (int gi = 0; gi < 3; gi++) {
        float g = gi == 0 ? 0.0f : (gi == 1 ? 0.6f : -0.3f);
        v3 din = v3_normalize(v3_make(0.3f, -0.5f, 0.8f));
        double integral = 0.0, mean_cos = 0.0;
        int k = 20000;
        medium_rng rng = medium_rng_seed(7, 8, (uint32_t)gi);
        for (int i = 0; i < k; i++) {
            float z = 1.0f - 2.0f * medium_rng_next(&rng), ph = 6.2831853f * medium_rng_next(&rng);
            float rr = sqrtf(fmaxf(0.0f, 1.0f - z * z));
            integral += medium_phase(g, din, v3_make(rr * cosf(ph), rr * sinf(ph), z)) * 4.0 * 3.14159265358979;
            v3 w = medium_phase_sample(g, din, medium_rng_next(&rng), medium_rng_next(&rng));
            mean_cos += v3_dot(w, din);
        }
        CHECKF(fabs(integral / k - 1.0) < 0.03, "g %.1f: phase integral %.4f", g, integral / k);
        CHECKF(fabs(mean_cos / k - g) < 0.02, "g %.1f: sampled mean cosine %.4f", g, mean_cos / k);
    }
    rp_render_scene_release(s);
    rp_scene_data_free(&d);
    rp_device_release(dev);
}

/* An albedo-1 medium in a uniform environment of radiance 1: every path ends in the environment
 * with weight 1, so every pixel is 1 (direct lighting alone is darker: single scattering). */
static void test_furnace(void) {
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 2});
    for (int gi = 0; gi < 2; gi++) {
        rp_scene_data d;
        rp_render_scene *s = homogeneous(dev, &d, (rp_medium_desc){.hg_g = gi ? 0.6f : 0.0f});
        if (!s) continue;
        rp_camera cam = {.type = RP_CAMERA_PINHOLE};
        cam.pinhole = (rp_pinhole_camera){.eye = {2.6f, 3.6f, 9.0f}, .look = {2.6f, 3.6f, 4.6f}, .up = {0, 1, 0},
                                          .fov_deg = 30};
        int spp = rp_test_sanitized() ? 16 : 64;
        rp_render_desc rd = {.width = 24, .height = 24, .spp = spp, .integrator = RP_INTEGRATOR_PATH, .camera = &cam};
        float *px = render(s, &rd);
        CHECK(px != NULL);
        if (px) {
            double m = mean_of(px, 24 * 24 * 3);
            printf("furnace (g %.1f): mean radiance %.4f at %d spp\n", gi ? 0.6 : 0.0, m, spp);
            CHECKF(fabs(m - 1.0) < 0.02, "furnace (g %.1f): mean radiance %.4f, want 1 within 2%%", gi ? 0.6 : 0.0, m);
            free(px);
        }
        rd.integrator = RP_INTEGRATOR_DIRECT;
        px = render(s, &rd);
        if (px) {
            double m = mean_of(px, 24 * 24 * 3);
            CHECKF(m > 0.3 && m < 0.99, "single scattering: mean radiance %.4f, below the furnace's 1", m);
            free(px);
        }
        rp_render_scene_release(s);
        rp_scene_data_free(&d);
    }
    /* Surfaces in the medium: a white (kd 1) sphere inside it does not change the furnace. */
    {
        rp_scene_data d;
        rp_render_scene_release(homogeneous(dev, &d, (rp_medium_desc){0})); /* d's volume, then surfaces */
        d.sphere_count = 1;
        d.spheres = calloc(1, sizeof *d.spheres);
        d.spheres[0] = (rp_sphere_data){.center = {2.6f, 3.6f, 4.6f}, .radius = 0.8f, .material = 0};
        d.material_count = 1;
        d.materials = calloc(1, sizeof *d.materials);
        for (int c = 0; c < 3; c++) d.materials[0].kd[c] = 1.0f;
        d.materials[0].ior = 1.0f;
        d.materials[0].illum = -1;
        d.materials[0].map_kd = -1;
        char err[256] = "";
        rp_render_scene *s = rp_render_scene_new(dev, &d, &(rp_render_scene_desc){.medium = {.density_scale = SIGMA / 0.5f},
                                                                                 .environment_scale = {1, 1, 1}},
                                                 err, sizeof err);
        CHECKF(s != NULL, "%s", err);
        rp_camera cam = {.type = RP_CAMERA_PINHOLE};
        cam.pinhole = (rp_pinhole_camera){.eye = {2.6f, 3.6f, 9.0f}, .look = {2.6f, 3.6f, 4.6f}, .up = {0, 1, 0},
                                          .fov_deg = 30};
        int spp = rp_test_sanitized() ? 16 : 64;
        rp_render_desc rd = {.width = 24, .height = 24, .spp = spp, .integrator = RP_INTEGRATOR_PATH, .camera = &cam};
        float *px = s ? render(s, &rd) : NULL;
        CHECK(px != NULL);
        if (px) {
            double m = mean_of(px, 24 * 24 * 3), mid = px[(12 * 24 + 12) * 3];
            printf("furnace with a white sphere in the medium: mean radiance %.4f at %d spp\n", m, spp);
            CHECKF(fabs(m - 1.0) < 0.02, "furnace with a sphere: mean radiance %.4f, want 1 within 2%%", m);
            CHECKF(fabs(mid - 1.0) < 0.5, "furnace with a sphere: the middle pixel %.4f", mid);
            free(px);
        }
        rp_render_scene_release(s);
        rp_scene_data_free(&d);
    }
    rp_device_release(dev);
}

static void test_cloud_render(void) {
    char buf[1024], env_buf[1024];
    const char *path = rp_test_scene(CLOUD, buf, sizeof buf);
    const char *env = rp_test_scene("env/studio_small_03_1k.hdr", env_buf, sizeof env_buf);
    CHECK(path && env);
    if (!path || !env) return;
    rp_scene_data d;
    char err[512] = "";
    CHECKF(rp_scene_data_load(path, &d, err, sizeof err), "%s", err);
    int w = 40, h = 40;
    float *img[2] = {NULL, NULL};
    for (int t = 1; t <= 2; t++) {
        rp_device *dev = rp_device_new(&(rp_device_desc){.threads = t});
        rp_render_scene *s = rp_render_scene_new(dev, &d, &(rp_render_scene_desc){.environment = env}, err, sizeof err);
        CHECKF(s != NULL, "%s", err);
        if (s) {
            rp_render_desc rd = {.width = w, .height = h, .spp = rp_test_sanitized() ? 2 : 8,
                                 .integrator = RP_INTEGRATOR_PATH, .tile_size = 8};
            img[t - 1] = render(s, &rd);
            CHECK(img[t - 1] != NULL);
        }
        if (s && t == 1) { /* every integrator shows the cloud: its middle is not the background */
            static const rp_integrator_type others[] = {RP_INTEGRATOR_EYELIGHT, RP_INTEGRATOR_WHITTED,
                                                        RP_INTEGRATOR_AO, RP_INTEGRATOR_DIRECT, RP_INTEGRATOR_IR};
            for (size_t k = 0; k < sizeof others / sizeof others[0]; k++) {
                rp_render_desc rd = {.width = 16, .height = 16, .spp = 4, .integrator = others[k]};
                float *px = render(s, &rd);
                CHECKF(px != NULL, "integrator %d failed", (int)others[k]);
                if (!px) continue;
                float mid = 0.0f, corner = px[1];
                for (int y = 6; y < 10; y++)
                    for (int x = 6; x < 10; x++) mid += px[(y * 16 + x) * 3 + 1] / 16.0f;
                CHECKF(mid > 0.05f && fabsf(mid - corner) > 0.02f, "integrator %d: middle %g, corner %g", (int)others[k],
                       mid, corner);
                free(px);
            }
        }
        rp_render_scene_release(s);
        rp_device_release(dev);
    }
    if (img[0] && img[1]) {
        size_t n = (size_t)w * h * 3;
        CHECK(memcmp(img[0], img[1], n * sizeof(float)) == 0);
        double m = mean_of(img[0], (int)n), var = 0.0, lo = 1e30, hi = -1e30;
        for (size_t i = 0; i < n; i++) {
            var += (img[0][i] - m) * (img[0][i] - m);
            lo = fmin(lo, img[0][i]);
            hi = fmax(hi, img[0][i]);
        }
        var /= (double)n;
        CHECKF(m > 0.02, "mean %g: black", m);
        CHECKF(sqrt(var) > 0.2 * m && hi - lo > 0.2, "std %g, range %g-%g: uniform", sqrt(var), lo, hi);
        /* the cloud is brighter than the dark studio around it */
        double mid = 0.0, edge = 0.0;
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                double v = img[0][(y * w + x) * 3 + 1];
                bool centre = abs(x - w / 2) < 4 && abs(y - h / 2) < 4, border = x < 3 || y < 3;
                mid += centre ? v : 0.0;
                edge += border ? v : 0.0;
            }
        CHECKF(mid / 64 > 2.0 * edge / (3 * w + 3 * (h - 3)), "cloud %g against background %g", mid / 64,
               edge / (3 * w + 3 * (h - 3)));
    }
    free(img[0]);
    free(img[1]);
    rp_scene_data_free(&d);
}

int main(void) {
    test_load();
    test_transmittance();
    test_furnace();
    test_cloud_render();
    return RP_TEST_END();
}
