// rp-test: labels=core
/* The public API at its boundary: error codes, the error callback and the first-error-per-thread
 * rule, refcounts and allocator hooks (every byte given back), NaN/Inf and out-of-range
 * primitives rejected with a counted warning, degenerate and huge/tiny inputs, spheres, user
 * geometry, masks, parallel_for. */
#include <math.h>
#include <pthread.h>

#include "mesh_gen.h"
#include "raypack.h"
#include "rp_test.h"
#include "sys/sys.h"

typedef struct counting {
    long live_blocks;
    long long live_bytes;
    long total;
} counting;

static void *count_alloc(void *user, void *ptr, size_t old_size, size_t new_size, size_t align) {
    counting *c = user;
    if (new_size == 0) {
        if (ptr) c->live_blocks--, c->live_bytes -= (long long)old_size;
        free(ptr);
        return NULL;
    }
    void *p = NULL;
    if (posix_memalign(&p, align < sizeof(void *) ? sizeof(void *) : align, new_size) != 0) return NULL;
    c->live_blocks++, c->live_bytes += (long long)new_size, c->total++;
    return p;
}

typedef struct errors {
    int count;
    rp_error last;
    int warnings;
    char message[256];
} errors;

static void on_error(void *user, rp_error code, const char *message) {
    errors *e = user;
    e->count++, e->last = code;
    snprintf(e->message, sizeof e->message, "%s", message);
}

static void on_log(void *user, rp_log_level level, const char *message) {
    errors *e = user;
    if (level == RP_LOG_WARNING) e->warnings++;
    snprintf(e->message, sizeof e->message, "%s", message);
}

static rp_rayhit ray_at(float ox, float oy, float oz, float dx, float dy, float dz) {
    rp_rayhit rh = {.ray = {.org_x = ox, .org_y = oy, .org_z = oz, .dir_x = dx, .dir_y = dy, .dir_z = dz,
                            .tnear = 0.0f, .tfar = INFINITY, .mask = ~0u}};
    rh.hit.geom_id = RP_INVALID_ID;
    return rh;
}

typedef struct user_spheres {
    float c[3], r;
} user_spheres;

static void ub(void *user, uint32_t prim, rp_bounds *out) {
    const user_spheres *s = (const user_spheres *)user + prim;
    *out = (rp_bounds){s->c[0] - s->r, s->c[1] - s->r, s->c[2] - s->r, 0, s->c[0] + s->r, s->c[1] + s->r, s->c[2] + s->r, 0};
}
/* A user primitive that is a plane square at z = c[2] of half size r. */
static bool ui(void *user, uint32_t prim, rp_ray *ray, rp_hit *hit) {
    const user_spheres *s = (const user_spheres *)user + prim;
    if (ray->dir_z == 0.0f) return false;
    float t = (s->c[2] - ray->org_z) / ray->dir_z;
    float x = ray->org_x + t * ray->dir_x, y = ray->org_y + t * ray->dir_y;
    if (t < ray->tnear || t > ray->tfar || fabsf(x - s->c[0]) > s->r || fabsf(y - s->c[1]) > s->r) return false;
    ray->tfar = t;
    hit->Ng_x = 0, hit->Ng_y = 0, hit->Ng_z = 1, hit->u = 0, hit->v = 0;
    return true;
}
static bool uo(void *user, uint32_t prim, const rp_ray *ray) {
    rp_ray r = *ray;
    rp_hit h;
    return ui(user, prim, &r, &h);
}

typedef struct pf {
    uint32_t *seen;
    int threads;
} pf;
static void pf_task(void *user, uint32_t index, uint32_t thread) {
    pf *p = user;
    __atomic_fetch_add(&p->seen[index], 1u, __ATOMIC_RELAXED);
    if ((int)thread >= p->threads) __atomic_fetch_add(&p->seen[0], 1000u, __ATOMIC_RELAXED);
}

static void *other_thread(void *dev) { return (void *)(intptr_t)rp_device_get_error(dev); }

int main(void) {
    counting mem = {0};
    errors err = {0};
    rp_device *dev = rp_device_new(&(rp_device_desc){.threads = 3, .alloc = count_alloc, .alloc_user = &mem,
                                                     .error = on_error, .error_user = &err, .log = on_log, .log_user = &err});
    CHECK(dev != NULL);
    CHECK(rp_device_thread_count(dev) == 3);
    CHECK(rp_device_isa(dev) == 1 || rp_device_isa(dev) == 4 || rp_device_isa(dev) == 8 || rp_device_isa(dev) == 16);
    /* isa 0 is sys_cpu_simd_auto: the widest the CPU has, or AVX2 in its place on a CPU whose AVX-512
     * lowers the clock; the widest can still be asked for */
    int widest = sys_cpu_simd_width(), auto_isa = sys_cpu_simd_auto();
    CHECK(rp_device_isa(dev) == auto_isa);
    CHECK(auto_isa == widest || (widest == 16 && auto_isa == 8));
    rp_device *wide = rp_device_new(&(rp_device_desc){.threads = 1, .isa = widest});
    CHECK(wide && rp_device_isa(wide) == widest);
    rp_device_release(wide);
    CHECK(strcmp(rp_error_string(RP_ERROR_NOT_COMMITTED), "the scene was edited and not committed since") == 0);
    CHECK(strcmp(rp_error_string((rp_error)999), "invalid error code") == 0);
    CHECK(rp_device_new(&(rp_device_desc){.threads = -1}) == NULL);
    CHECK(rp_device_new(&(rp_device_desc){.isa = 3}) == NULL);

    /* bad arguments */
    CHECK(rp_geometry_new(dev, (rp_geometry_type)7) == NULL);
    CHECK(err.last == RP_ERROR_INVALID_ARGUMENT && err.count == 1);
    CHECK(rp_scene_new(dev, &(rp_scene_desc){.bvh_width = 3}) == NULL);
    rp_geometry *tri = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    rp_geometry_set_buffer(tri, RP_BUFFER_INDEX, RP_FORMAT_FLOAT3, NULL, 0, 0, 0);
    CHECK(err.last == RP_ERROR_INVALID_ARGUMENT);
    rp_geometry_set_buffer(tri, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, (const float[3]){0}, 0, 8, 1); /* stride < 12 */
    CHECK(err.last == RP_ERROR_INVALID_ARGUMENT);
    /* the first error of this thread is kept until read, then cleared; other threads have their own */
    CHECK(rp_device_get_error(dev) == RP_ERROR_INVALID_ARGUMENT);
    CHECK(rp_device_get_error(dev) == RP_ERROR_NONE);
    pthread_t th;
    rp_geometry_set_mask(NULL, 0); /* NULL handles are ignored */
    rp_geometry_commit(tri);       /* no buffers */
    CHECK(err.last == RP_ERROR_INVALID_GEOMETRY);
    pthread_create(&th, NULL, other_thread, dev);
    void *other = NULL;
    pthread_join(th, &other);
    CHECK((rp_error)(intptr_t)other == RP_ERROR_NONE);
    CHECK(rp_device_get_error(dev) == RP_ERROR_INVALID_GEOMETRY);

    /* queries on an uncommitted scene */
    rp_scene *scene = rp_scene_new(dev, NULL);
    rp_rayhit rh = ray_at(0, 0, -5, 0, 0, 1);
    rp_intersect1(scene, &rh);
    CHECK(rp_device_get_error(dev) == RP_ERROR_NOT_COMMITTED);
    CHECK(rh.hit.geom_id == RP_INVALID_ID && rh.ray.tfar == INFINITY);
    /* a committed empty scene: no hit, no error */
    CHECK(rp_scene_commit(scene) == RP_ERROR_NONE);
    rp_intersect1(scene, &rh);
    CHECK(rh.hit.geom_id == RP_INVALID_ID && rp_device_get_error(dev) == RP_ERROR_NONE);
    /* a geometry missing its index buffer fails the commit */
    rp_scene_attach(scene, tri);
    CHECK(rp_scene_commit(scene) == RP_ERROR_INVALID_GEOMETRY);
    rp_intersect1(scene, &rh);
    CHECK(rp_device_get_error(dev) == RP_ERROR_INVALID_GEOMETRY); /* first error kept: the commit's */

    /* library-owned buffers: 2 good triangles, 1 with NaN, 1 with an out-of-range index */
    float *v = rp_geometry_new_buffer(tri, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, 0, 7);
    uint32_t *ix = rp_geometry_new_buffer(tri, RP_BUFFER_INDEX, RP_FORMAT_UINT3, 0, 4);
    CHECK(v && ix);
    float vv[21] = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0, NAN, 0, 0, 0, 1, 0, 0, 0, 1};
    memcpy(v, vv, sizeof vv);
    uint32_t ii[12] = {0, 1, 2, 0, 2, 3, 4, 5, 6, 0, 1, 9};
    memcpy(ix, ii, sizeof ii);
    rp_geometry_commit(tri);
    err.warnings = 0;
    CHECK(rp_scene_commit(scene) == RP_ERROR_NONE);
    rp_scene_stats st;
    rp_scene_get_stats(scene, &st);
    CHECK(st.triangles == 2 && st.rejected_prims == 2);
    CHECKF(err.warnings == 1 && strstr(err.message, "2 primitives rejected"), "warning: %s", err.message);
    rh = ray_at(0.5f, -0.5f, -5, 0, 0, 1);
    rp_intersect1(scene, &rh);
    CHECK(rh.hit.geom_id == 0 && rh.hit.prim_id == 0 && fabsf(rh.ray.tfar - 5.0f) < 1e-6f);
    CHECK(rh.hit.Ng_z > 0.0f && fabsf(rh.hit.u + rh.hit.v - 0.5f) < 1.0f);
    rh = ray_at(-0.5f, 0.5f, -5, 0, 0, 1);
    rp_intersect1(scene, &rh);
    CHECK(rh.hit.prim_id == 1);
    /* tnear / tfar bound the segment */
    rh = ray_at(0.5f, -0.5f, -5, 0, 0, 1);
    rh.ray.tfar = 4.9f;
    rp_intersect1(scene, &rh);
    CHECK(rh.hit.geom_id == RP_INVALID_ID);
    rh.ray.tnear = 5.1f, rh.ray.tfar = INFINITY;
    rp_intersect1(scene, &rh);
    CHECK(rh.hit.geom_id == RP_INVALID_ID);
    /* masks */
    rp_geometry_set_mask(tri, 2);
    CHECK(rp_scene_commit(scene) == RP_ERROR_NONE);
    rh = ray_at(0.5f, -0.5f, -5, 0, 0, 1);
    rh.ray.mask = 1;
    rp_intersect1(scene, &rh);
    CHECK(rh.hit.geom_id == RP_INVALID_ID);
    rh.ray.mask = 2;
    rp_intersect1(scene, &rh);
    CHECK(rh.hit.geom_id == 0);

    /* spheres and user geometry beside triangles, with strided shared buffers */
    float spheres[2][5] = {{0, 0, 3, 0.5f, 99}, {0, 0, 6, 1.0f, 99}};
    rp_geometry *sph = rp_geometry_new(dev, RP_GEOMETRY_SPHERE);
    rp_geometry_set_buffer(sph, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT4, spheres, 0, 5 * sizeof(float), 2);
    uint32_t sid = rp_scene_attach(scene, sph);
    user_spheres squares[1] = {{{0, 0, -2}, 0.25f}};
    rp_geometry *usr = rp_geometry_new(dev, RP_GEOMETRY_USER);
    rp_geometry_set_user(usr, 1, ub, ui, uo, squares);
    uint32_t uid = rp_scene_attach(scene, usr);
    rp_geometry_set_mask(tri, ~0u);
    CHECK(rp_scene_commit(scene) == RP_ERROR_NONE);
    rh = ray_at(0, 0, 10, 0, 0, -1); /* from above: the big sphere first */
    rp_intersect1(scene, &rh);
    CHECKF(rh.hit.geom_id == sid && rh.hit.prim_id == 1 && fabsf(rh.ray.tfar - 3.0f) < 1e-5f, "sphere hit %u %u %g",
           rh.hit.geom_id, rh.hit.prim_id, (double)rh.ray.tfar);
    rh = ray_at(0, 0, -10, 0, 0, 1); /* from below: the user square at z = -2 */
    rp_intersect1(scene, &rh);
    CHECK(rh.hit.geom_id == uid && fabsf(rh.ray.tfar - 8.0f) < 1e-5f);
    rh = ray_at(0.6f, 0.6f, -10, 0, 0, 1); /* misses the square, hits the triangles */
    rp_intersect1(scene, &rh);
    CHECK(rh.hit.geom_id == 0);
    rp_ray sr = ray_at(0, 0, 10, 0, 0, -1).ray;
    sr.tfar = 3.5f;
    rp_occluded1(scene, &sr);
    CHECK(sr.tfar == -INFINITY);
    sr = ray_at(3, 3, 10, 0, 0, -1).ray;
    rp_occluded1(scene, &sr);
    CHECK(sr.tfar == INFINITY);
    /* the same through a packet, with dead lanes untouched */
    rp_rayhit4 p4;
    int32_t valid[4] = {-1, 0, -1, -1};
    rp_rayhit r4[4] = {ray_at(0, 0, 10, 0, 0, -1), ray_at(0, 0, 10, 0, 0, -1), ray_at(0, 0, -10, 0, 0, 1),
                       ray_at(0.5f, -0.5f, -5, 0, 0, 1)};
    for (int i = 0; i < 4; i++) {
        p4.ray.org_x[i] = r4[i].ray.org_x, p4.ray.org_y[i] = r4[i].ray.org_y, p4.ray.org_z[i] = r4[i].ray.org_z;
        p4.ray.dir_x[i] = r4[i].ray.dir_x, p4.ray.dir_y[i] = r4[i].ray.dir_y, p4.ray.dir_z[i] = r4[i].ray.dir_z;
        p4.ray.tnear[i] = 0, p4.ray.tfar[i] = INFINITY, p4.ray.mask[i] = ~0u, p4.hit.geom_id[i] = RP_INVALID_ID;
    }
    rp_intersect4(scene, valid, &p4);
    CHECK(p4.hit.geom_id[0] == sid && p4.hit.geom_id[1] == RP_INVALID_ID && p4.ray.tfar[1] == INFINITY);
    CHECK(p4.hit.geom_id[2] == uid && p4.hit.geom_id[3] == 0 && fabsf(p4.ray.tfar[3] - 5.0f) < 1e-6f);
    /* detach */
    rp_scene_detach(scene, sid);
    rp_scene_detach(scene, sid);
    CHECK(rp_device_get_error(dev) == RP_ERROR_INVALID_ARGUMENT);
    rp_intersect1(scene, &rh);
    CHECK(rp_device_get_error(dev) == RP_ERROR_NOT_COMMITTED);
    CHECK(rp_scene_commit(scene) == RP_ERROR_NONE);
    rp_geometry_release(sph);
    rp_geometry_release(usr);
    rp_geometry_release(tri);

    /* degenerate input: all triangles identical, and huge / tiny coordinates */
    rp_scene *deg = rp_scene_new(dev, NULL);
    rp_geometry *dg = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    float *dv = rp_geometry_new_buffer(dg, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, 0, 9);
    uint32_t *di = rp_geometry_new_buffer(dg, RP_BUFFER_INDEX, RP_FORMAT_UINT3, 0, 5003);
    float dvv[27] = {0, 0, 0, 1, 0, 0, 0, 1, 0, -3e15f, -3e15f, 1, 3e15f, -3e15f, 1, 0, 3e15f, 1, 1e-30f, 1e-30f, 2, 2e-30f, 1e-30f, 2, 1e-30f, 2e-30f, 2};
    memcpy(dv, dvv, sizeof dvv);
    for (int i = 0; i < 5000; i++) di[3 * i] = 0, di[3 * i + 1] = 1, di[3 * i + 2] = 2;
    di[15000] = 3, di[15001] = 4, di[15002] = 5, di[15003] = 6, di[15004] = 7, di[15005] = 8, di[15006] = 0, di[15007] = 0, di[15008] = 0;
    rp_scene_attach(deg, dg);
    rp_geometry_release(dg);
    CHECK(rp_scene_commit(deg) == RP_ERROR_NONE);
    rp_scene_get_stats(deg, &st);
    /* the last triangle has three equal vertices: left out, and counted */
    CHECK(st.triangles == 5002 && st.degenerate_prims == 1 && st.depth <= 100);
    rh = ray_at(0.2f, 0.2f, -1, 0, 0, 1);
    rp_intersect1(deg, &rh);
    CHECK(rh.hit.geom_id == 0 && rh.hit.prim_id == 0); /* lowest id among 5000 duplicates */
    rh = ray_at(1e14f, 0, -1, 0, 0, 1);
    rp_intersect1(deg, &rh);
    CHECKF(rh.hit.prim_id == 5000 && fabsf(rh.ray.tfar - 2.0f) < 1e-6f, "huge triangle: geom %u prim %u t %g", rh.hit.geom_id, rh.hit.prim_id, (double)rh.ray.tfar);
    /* coordinates near FLT_MAX build fine (the edge functions of such triangles overflow float,
     * so they are not hit: the same limit as every float ray tracer) */
    dv[9] = -3e38f, dv[12] = 3e38f, dv[16] = 3e38f;
    CHECK(rp_scene_commit(deg) == RP_ERROR_NONE);
    rp_scene_get_stats(deg, &st);
    CHECK(st.triangles == 5002);
    rh = ray_at(0.2f, 0.2f, -1, 0, 0, 1);
    rp_intersect1(deg, &rh);
    CHECK(rh.hit.prim_id == 0);
    rp_scene_release(deg);

    /* SAH termination: 64 slivers with one box (and one centroid) are not split below the
     * 32-primitive leaf limit, where 4-primitive leaves made 16 leaves of the same box */
    rp_scene *fan = rp_scene_new(dev, NULL);
    rp_geometry *fg = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    float *fv = rp_geometry_new_buffer(fg, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, 0, 66);
    uint32_t *fi = rp_geometry_new_buffer(fg, RP_BUFFER_INDEX, RP_FORMAT_UINT3, 0, 64);
    fv[0] = 0, fv[1] = 0, fv[2] = 0, fv[3] = 10, fv[4] = 1, fv[5] = 0;
    for (int i = 0; i < 64; i++) {
        fv[6 + 3 * i] = 0.15f * (float)(i + 1), fv[7 + 3 * i] = 1.0f, fv[8 + 3 * i] = 0.0f;
        fi[3 * i] = 0, fi[3 * i + 1] = 1, fi[3 * i + 2] = (uint32_t)(2 + i);
    }
    rp_scene_attach(fan, fg);
    rp_geometry_release(fg);
    CHECK(rp_scene_commit(fan) == RP_ERROR_NONE);
    rp_scene_get_stats(fan, &st);
    CHECKF(st.triangles == 64 && st.leaves == 2, "fan: %llu triangles in %llu leaves",
           (unsigned long long)st.triangles, (unsigned long long)st.leaves);
    rh = ray_at(9.9f, 0.995f, -1, 0, 0, 1);
    rp_intersect1(fan, &rh);
    CHECK(rh.hit.prim_id == 0 && fabsf(rh.ray.tfar - 1.0f) < 1e-6f); /* every sliver covers it */
    rp_scene_release(fan);

    {
        /* 200000 triangles in two geometries, gathered by several tasks: every 7th degenerate, every
         * 11th with a bad index, counted across the tasks; the kept ones still hit where they lie; on
         * one thread the same tree (the threads only share the work) */
        uint32_t big_n = 100000;
        float *gv[2];
        uint32_t *gi[2];
        for (int gk = 0; gk < 2; gk++) {
            gv[gk] = malloc((size_t)big_n * 9 * sizeof(float));
            gi[gk] = malloc((size_t)big_n * 3 * sizeof(uint32_t));
            for (uint32_t i = 0; i < big_n; i++) {
                float x = (float)(i % 1000), y = (float)(i / 1000) + 200.0f * (float)gk;
                float tv9[9] = {x, y, 0, x + 0.9f, y, 0, x, y + 0.9f, 0};
                if (i % 7 == 0) tv9[3] = tv9[0], tv9[4] = tv9[1], tv9[5] = tv9[2];
                memcpy(gv[gk] + 9 * i, tv9, sizeof tv9);
                gi[gk][3 * i] = 3 * i, gi[gk][3 * i + 1] = 3 * i + 1;
                gi[gk][3 * i + 2] = i % 11 == 5 ? 3 * big_n + 7 : 3 * i + 2;
            }
        }
        rp_device *dev1 = rp_device_new(&(rp_device_desc){.threads = 1});
        rp_scene_stats st1 = {0};
        for (int pass = 0; pass < 2; pass++) {
            rp_device *d = pass ? dev1 : dev;
            rp_scene *bigs = rp_scene_new(d, NULL);
            for (int gk = 0; gk < 2; gk++) {
                rp_geometry *bg = rp_geometry_new(d, RP_GEOMETRY_TRIANGLE);
                rp_geometry_set_buffer(bg, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, gv[gk], 0, 0, 3 * big_n);
                rp_geometry_set_buffer(bg, RP_BUFFER_INDEX, RP_FORMAT_UINT3, gi[gk], 0, 0, big_n);
                rp_geometry_commit(bg);
                rp_scene_attach(bigs, bg);
                rp_geometry_release(bg);
            }
            CHECK(rp_scene_commit(bigs) == RP_ERROR_NONE);
            rp_scene_get_stats(bigs, pass ? &st1 : &st);
            rh = ray_at(123.2f, 245.2f, -1, 0, 0, 1); /* triangle 45123 of the second geometry */
            rp_intersect1(bigs, &rh);
            CHECK(rh.hit.geom_id == 1 && rh.hit.prim_id == 45123);
            rh = ray_at(77.2f, 0.2f, -1, 0, 0, 1); /* triangle 77: degenerate */
            rp_intersect1(bigs, &rh);
            CHECK(rh.hit.geom_id == RP_INVALID_ID);
            rp_scene_release(bigs);
        }
        uint64_t ndeg = 0, nbad = 0;
        for (uint32_t i = 0; i < big_n; i++) {
            if (i % 11 == 5) nbad++;
            else if (i % 7 == 0) ndeg++;
        }
        CHECKF(st.degenerate_prims == 2 * ndeg && st.rejected_prims == 2 * nbad &&
                   st.triangles == 2 * (big_n - ndeg - nbad),
               "big: %llu triangles, %llu degenerate, %llu rejected", (unsigned long long)st.triangles,
               (unsigned long long)st.degenerate_prims, (unsigned long long)st.rejected_prims);
        CHECKF(st1.triangles == st.triangles && st1.binary_nodes == st.binary_nodes && st1.leaves == st.leaves &&
                   st1.depth == st.depth && st1.sah_cost == st.sah_cost && st1.wide_nodes == st.wide_nodes,
               "1 thread: %llu nodes (%llu wide), SAH %.6f; 3 threads: %llu nodes (%llu wide), SAH %.6f",
               (unsigned long long)st1.binary_nodes, (unsigned long long)st1.wide_nodes, st1.sah_cost,
               (unsigned long long)st.binary_nodes, (unsigned long long)st.wide_nodes, st.sah_cost);
        rp_device_release(dev1);
        for (int gk = 0; gk < 2; gk++) free(gv[gk]), free(gi[gk]);
    }

    /* short rays starting near a large triangle keep an accurate distance (a reflection ray
     * leaving a wall towards a big floor 0.03 away), compared with the plane distance in double */
    {
        rp_scene *big = rp_scene_new(dev, NULL);
        rp_geometry *bg = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
        float bv[9] = {-500, 0.0f, -500, 700, 0.37f, -400, -300, -0.21f, 650};
        uint32_t bi[3] = {0, 1, 2};
        rp_geometry_set_buffer(bg, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, bv, 0, 0, 3);
        rp_geometry_set_buffer(bg, RP_BUFFER_INDEX, RP_FORMAT_UINT3, bi, 0, 0, 1);
        rp_scene_attach(big, bg);
        rp_geometry_release(bg);
        CHECK(rp_scene_commit(big) == RP_ERROR_NONE);
        test_rng g = {5};
        double worst = 0.0;
        for (int i = 0; i < 2000; i++) {
            float o[3] = {(test_rng_float(&g) - 0.5f) * 200.0f, 0.0f, (test_rng_float(&g) - 0.5f) * 200.0f};
            float d[3] = {test_rng_float(&g) - 0.5f, -0.05f - test_rng_float(&g), test_rng_float(&g) - 0.5f};
            /* lift the origin 0.01..0.05 above the plane */
            double e1[3] = {(double)bv[3] - bv[0], (double)bv[4] - bv[1], (double)bv[5] - bv[2]};
            double e2[3] = {(double)bv[6] - bv[0], (double)bv[7] - bv[1], (double)bv[8] - bv[2]};
            double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
            double y = bv[1] - (n[0] * (o[0] - bv[0]) + n[2] * (o[2] - bv[2])) / n[1];
            o[1] = (float)(y + 0.01 + 0.04 * test_rng_float(&g));
            double t = (n[0] * ((double)bv[0] - o[0]) + n[1] * ((double)bv[1] - o[1]) + n[2] * ((double)bv[2] - o[2])) /
                       (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]);
            rh = ray_at(o[0], o[1], o[2], d[0], d[1], d[2]);
            rp_intersect1(big, &rh);
            if (rh.hit.geom_id != 0) {
                worst = 1.0;
                continue;
            }
            double rel = fabs(rh.ray.tfar - t) / t;
            worst = rel > worst ? rel : worst;
        }
        CHECKF(worst < 1e-4, "short rays near a large triangle: worst relative t error %g", worst);
        rp_scene_release(big);
    }

    /* Axis-parallel rays lying in box faces at coordinate 0, where the boxes' relative margin is 0:
     * a grid of 2 x 32 x 32 triangles at z = 2 whose vertices lie on x, y = -1 .. 1 in steps of
     * 1/16, rays along +z through x = 0 (or y = 0) exactly. The slab test takes their zero direction
     * components as +-1e-18 (the zero's sign picks the side of the face) and keeps them inside the
     * faces at 0 only for t up to the absolute margin (box_pad_abs) times 1e18; the watertight test
     * gives the edge's hit to the triangle on the zero's side, so the hits are found even with no
     * absolute margin (measured), and must stay found with every structure, query and zero sign. */
    for (int acc = 0; acc < RP_ACCEL_COUNT; acc++) {
        enum { G = 32, GV = G + 1 };
        rp_scene *pl = rp_scene_new(dev, &(rp_scene_desc){.accel = (rp_accel_type)acc});
        rp_geometry *pg = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
        float *pv = rp_geometry_new_buffer(pg, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, 0, GV * GV);
        uint32_t *pi = rp_geometry_new_buffer(pg, RP_BUFFER_INDEX, RP_FORMAT_UINT3, 0, 2 * G * G);
        for (int j = 0; j < GV; j++)
            for (int i = 0; i < GV; i++) {
                float *pvi = pv + 3 * (GV * j + i);
                pvi[0] = -1.0f + (float)i / 16.0f, pvi[1] = -1.0f + (float)j / 16.0f, pvi[2] = 2.0f;
            }
        for (uint32_t j = 0, t = 0; j < G; j++)
            for (uint32_t i = 0; i < G; i++, t += 2) {
                uint32_t a = GV * j + i;
                uint32_t q[6] = {a, a + 1, a + GV + 1, a, a + GV + 1, a + GV};
                memcpy(pi + 3 * t, q, sizeof q);
            }
        rp_scene_attach(pl, pg);
        rp_geometry_release(pg);
        CHECK(rp_scene_commit(pl) == RP_ERROR_NONE);
        uint32_t lost = 0, lost16 = 0, lost_any = 0, n = 0;
        for (int k = 0; k < 64 * 8; k++, n++) {
            float c = -0.984375f + (float)(k % 64) / 32.0f; /* the other coordinate: on edges and inside */
            /* the zero components' signs choose the side of the face the slab test keeps them on */
            float zx = k / 64 & 1 ? -0.0f : 0.0f, zy = k / 128 & 1 ? -0.0f : 0.0f;
            rp_rayhit r1 = k / 256 ? ray_at(c, 0.0f, -1.0f, zx, zy, 1) : ray_at(0.0f, c, -1.0f, zx, zy, 1);
            rp_ray ro = r1.ray;
            rp_intersect1(pl, &r1);
            lost += !(r1.hit.geom_id == 0 && r1.ray.tfar == 3.0f);
            rp_occluded1(pl, &ro);
            lost_any += ro.tfar != -INFINITY;
            rp_rayhit16 r16;
            int32_t on[16];
            for (int l = 0; l < 16; l++) {
                on[l] = -1;
                r16.ray.org_x[l] = r1.ray.org_x, r16.ray.org_y[l] = r1.ray.org_y, r16.ray.org_z[l] = -1.0f;
                r16.ray.dir_x[l] = zx, r16.ray.dir_y[l] = zy, r16.ray.dir_z[l] = 1.0f;
                r16.ray.tnear[l] = 0.0f, r16.ray.tfar[l] = INFINITY, r16.ray.mask[l] = ~0u;
                r16.hit.geom_id[l] = RP_INVALID_ID;
            }
            rp_intersect16(pl, on, &r16);
            for (int l = 0; l < 16; l++) lost16 += !(r16.hit.geom_id[l] == 0 && r16.ray.tfar[l] == 3.0f);
        }
        CHECKF(lost == 0 && lost16 == 0 && lost_any == 0,
               "%s: rays in box faces at 0 lost %u closest hits, %u in 16-ray packets, %u occlusions of %u",
               rp_accel_name((rp_accel_type)acc), lost, lost16 / 16, lost_any, n);
        rp_scene_release(pl);
    }

    /* parallel_for hands out every index exactly once, on the device's threads */
    pf p = {calloc(10000, sizeof(uint32_t)), rp_device_thread_count(dev)};
    rp_device_parallel_for(dev, 10000, pf_task, &p);
    int once = 1;
    for (int i = 0; i < 10000; i++) once &= p.seen[i] == 1;
    CHECK(once);
    free(p.seen);

    rp_scene_release(scene);
    rp_device_release(dev);
    CHECKF(mem.live_blocks == 0 && mem.live_bytes == 0, "%ld blocks, %lld bytes not freed", mem.live_blocks, mem.live_bytes);
    CHECK(mem.total > 5);
    return RP_TEST_END();
}
