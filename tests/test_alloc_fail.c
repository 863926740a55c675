// rp-test: labels=core timeout=300
/* Allocation failures (issue 23): a device allocator that fails its k-th allocation, for every k
 * up to the number a whole round takes, during device creation, geometry buffers, commit (every
 * structure: triangle BVH, spheres, user geometry; 1 and 2 threads, so the parallel build paths
 * fail too) and rp_rayhit_n_alloc (rp_intersect_n's setup). Each call must return its error (or
 * NULL / false), give back every byte it took (counted here; LeakSanitizer in the ASan build
 * checks the rest), and leave the device usable: the next commit succeeds and answers rays like a
 * scene that never failed. */
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>

#include "mesh_gen.h"
#include "raypack.h"
#include "rp_test.h"

typedef struct failing {
    atomic_long count;     /* allocations so far while armed */
    atomic_long fail_at;   /* the allocation that fails (1-based); 0: none */
    atomic_long live_blocks;
    atomic_llong live_bytes;
    atomic_long failed;    /* how many allocations were refused */
    bool only;             /* refuse the k-th alone (else the k-th and every later one) */
} failing;

/* Every live block and its size, to check that frees pass the size the block was allocated with
 * (the hook's contract, as Lua's lua_Alloc: an arena allocator relies on it). */
enum { MAX_BLOCKS = 1 << 14 };
static struct {
    void *p;
    size_t size;
} blocks[MAX_BLOCKS];
static pthread_mutex_t blocks_lock = PTHREAD_MUTEX_INITIALIZER;
static atomic_long size_mismatches;

static void block_add(void *p, size_t size) {
    pthread_mutex_lock(&blocks_lock);
    for (int i = 0; i < MAX_BLOCKS; i++)
        if (!blocks[i].p) {
            blocks[i].p = p, blocks[i].size = size;
            break;
        }
    pthread_mutex_unlock(&blocks_lock);
}

static void block_remove(void *p, size_t size) {
    pthread_mutex_lock(&blocks_lock);
    for (int i = 0; i < MAX_BLOCKS; i++)
        if (blocks[i].p == p) {
            if (blocks[i].size != size) {
                if (atomic_fetch_add(&size_mismatches, 1) < 5)
                    fprintf(stderr, "block of %zu bytes freed as %zu bytes\n", blocks[i].size, size);
            }
            blocks[i].p = NULL;
            break;
        }
    pthread_mutex_unlock(&blocks_lock);
}

static void *fail_alloc(void *user, void *ptr, size_t old_size, size_t new_size, size_t align) {
    failing *f = user;
    if (ptr) block_remove(ptr, old_size);
    if (new_size == 0) {
        if (ptr) atomic_fetch_sub(&f->live_blocks, 1), atomic_fetch_sub(&f->live_bytes, (long long)old_size);
        free(ptr);
        return NULL;
    }
    long k = atomic_fetch_add(&f->count, 1) + 1;
    long at = atomic_load(&f->fail_at);
    if (at > 0 && (f->only ? k == at : k >= at)) { /* a call must give up, not carry on past it */
        atomic_fetch_add(&f->failed, 1);
        return NULL;
    }
    void *p = NULL;
    if (posix_memalign(&p, align < sizeof(void *) ? sizeof(void *) : align, new_size) != 0) return NULL;
    if (ptr) {
        memcpy(p, ptr, old_size < new_size ? old_size : new_size);
        free(ptr);
        atomic_fetch_sub(&f->live_blocks, 1), atomic_fetch_sub(&f->live_bytes, (long long)old_size);
    }
    atomic_fetch_add(&f->live_blocks, 1), atomic_fetch_add(&f->live_bytes, (long long)new_size);
    block_add(p, new_size);
    return p;
}

static void arm(failing *f, long k) {
    atomic_store(&f->count, 0);
    atomic_store(&f->failed, 0);
    atomic_store(&f->fail_at, k);
}

typedef struct ball {
    float c[3], r;
} ball;

static void ball_bounds(void *user, uint32_t prim, rp_bounds *out) {
    const ball *b = (const ball *)user + prim;
    *out = (rp_bounds){.lower_x = b->c[0] - b->r, .lower_y = b->c[1] - b->r, .lower_z = b->c[2] - b->r,
                       .upper_x = b->c[0] + b->r, .upper_y = b->c[1] + b->r, .upper_z = b->c[2] + b->r};
}

static bool ball_intersect(void *user, uint32_t prim, rp_ray *ray, rp_hit *hit) {
    (void)user, (void)prim, (void)ray, (void)hit; /* off to the side of every ray below */
    return false;
}

static bool ball_occluded(void *user, uint32_t prim, const rp_ray *ray) {
    (void)user, (void)prim, (void)ray;
    return false;
}

static test_mesh mesh;
static float spheres[4 * 8];
static ball balls[3];

/* A scene of a triangle soup, spheres and user boxes; NULL with *err when a step failed. */
static rp_scene *make_scene(rp_device *dev, rp_error *err) {
    *err = RP_ERROR_NONE;
    rp_scene *s = rp_scene_new(dev, NULL);
    if (!s) {
        *err = RP_ERROR_OUT_OF_MEMORY;
        return NULL;
    }
    rp_geometry *g = rp_geometry_new(dev, RP_GEOMETRY_TRIANGLE);
    if (g) {
        rp_geometry_set_buffer(g, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT3, mesh.v, 0, 0, mesh.nv);
        rp_geometry_set_buffer(g, RP_BUFFER_INDEX, RP_FORMAT_UINT3, mesh.idx, 0, 0, mesh.nt);
        if (rp_scene_attach(s, g) == RP_INVALID_ID) *err = RP_ERROR_OUT_OF_MEMORY;
        rp_geometry_release(g);
    } else {
        *err = RP_ERROR_OUT_OF_MEMORY;
    }
    rp_geometry *sp = *err ? NULL : rp_geometry_new(dev, RP_GEOMETRY_SPHERE);
    if (sp) {
        void *buf = rp_geometry_new_buffer(sp, RP_BUFFER_VERTEX, RP_FORMAT_FLOAT4, 0, 8);
        if (buf) memcpy(buf, spheres, sizeof spheres);
        else *err = RP_ERROR_OUT_OF_MEMORY;
        if (!*err && rp_scene_attach(s, sp) == RP_INVALID_ID) *err = RP_ERROR_OUT_OF_MEMORY;
        rp_geometry_release(sp);
    } else if (!*err) {
        *err = RP_ERROR_OUT_OF_MEMORY;
    }
    rp_geometry *u = *err ? NULL : rp_geometry_new(dev, RP_GEOMETRY_USER);
    if (u) {
        rp_geometry_set_user(u, 3, ball_bounds, ball_intersect, ball_occluded, balls);
        if (rp_scene_attach(s, u) == RP_INVALID_ID) *err = RP_ERROR_OUT_OF_MEMORY;
        rp_geometry_release(u);
    } else if (!*err) {
        *err = RP_ERROR_OUT_OF_MEMORY;
    }
    if (*err) {
        rp_scene_release(s);
        return NULL;
    }
    return s;
}

/* Fingerprint of a committed scene's answers: hits of a fan of rays through the soup. */
static uint64_t answers(rp_scene *s) {
    uint64_t h = 1469598103934665603ull;
    for (int i = 0; i < 256; i++) {
        float a = (float)i * 0.0245f;
        rp_rayhit rh = {.ray = {.org_x = 0.5f, .org_y = 0.5f, .org_z = -2.0f, .dir_x = 0.3f * cosf(a),
                                .dir_y = 0.3f * sinf(a), .dir_z = 1.0f, .tfar = INFINITY, .mask = ~0u}};
        rh.hit.geom_id = RP_INVALID_ID;
        rp_intersect1(s, &rh);
        uint32_t t;
        memcpy(&t, &rh.ray.tfar, 4);
        h = (h ^ rh.hit.geom_id ^ (uint64_t)rh.hit.prim_id << 20 ^ (uint64_t)t << 32) * 1099511628211ull;
    }
    return h;
}

/* Every k for one thread count; returns the number of rounds that saw a refused allocation. */
static int sweep(int threads, bool only, uint64_t expect) {
    failing f = {0};
    f.only = only;
    int refused_rounds = 0;
    for (long k = 1;; k++) {
        arm(&f, k);
        rp_device *dev = rp_device_new(&(rp_device_desc){.threads = threads, .alloc = fail_alloc, .alloc_user = &f});
        bool failed_somewhere = atomic_load(&f.failed) > 0;
        if (!dev) {
            CHECKF(failed_somewhere, "k=%ld: rp_device_new returned NULL with no refused allocation", k);
            CHECKF(atomic_load(&f.live_blocks) == 0, "k=%ld: failed rp_device_new leaked %ld blocks", k,
                   atomic_load(&f.live_blocks));
            refused_rounds++;
            continue;
        }
        rp_error err;
        rp_scene *s = make_scene(dev, &err);
        rp_error commit = RP_ERROR_NONE;
        if (s) commit = rp_scene_commit(s);
        failed_somewhere = atomic_load(&f.failed) > 0;
        if (s && commit == RP_ERROR_NONE && !failed_somewhere) {
            /* the commit took fewer than k: the k-th is rp_rayhit_n_alloc's, or none */
            rp_rayhit_n pk;
            bool got = rp_rayhit_n_alloc(dev, 16, &pk);
            CHECKF(got == (atomic_load(&f.failed) == 0), "k=%ld: rp_rayhit_n_alloc returned %d", k, got);
            if (got) rp_rayhit_n_free(dev, &pk);
            CHECK(answers(s) == expect);
            rp_scene_release(s);
            rp_device_release(dev);
            CHECKF(atomic_load(&f.live_blocks) == 0 && atomic_load(&f.live_bytes) == 0, "k=%ld: leak", k);
            if (got) break;
            refused_rounds++;
            continue;
        }
        /* an optional allocation (the parallel binning's scratch) may be refused with a fallback:
         * then the commit succeeds and must answer as always */
        CHECKF(!s || commit == RP_ERROR_OUT_OF_MEMORY || (commit == RP_ERROR_NONE && answers(s) == expect),
               "k=%ld: commit returned %s, not out of memory", k, rp_error_string(commit));
        CHECKF(s || err == RP_ERROR_OUT_OF_MEMORY, "k=%ld: scene set-up failed without an error", k);
        refused_rounds++;
        /* the device stays usable: disarmed, the same scene commits and answers as it should */
        arm(&f, 0);
        if (s) {
            CHECKF(rp_scene_commit(s) == RP_ERROR_NONE, "k=%ld: commit after a failed one failed", k);
            CHECKF(answers(s) == expect, "k=%ld: answers differ after a failed commit", k);
            rp_scene_release(s);
        }
        rp_scene *again = make_scene(dev, &err);
        CHECKF(again && rp_scene_commit(again) == RP_ERROR_NONE && answers(again) == expect,
               "k=%ld: a new scene on the device failed after the refused allocation", k);
        rp_scene_release(again);
        /* rp_intersect_n's packet set-up: fails cleanly, then works */
        arm(&f, 1);
        rp_rayhit_n pk;
        CHECKF(!rp_rayhit_n_alloc(dev, 16, &pk), "k=%ld: rp_rayhit_n_alloc succeeded with no memory", k);
        arm(&f, 0);
        CHECK(rp_rayhit_n_alloc(dev, 16, &pk));
        rp_rayhit_n_free(dev, &pk);
        rp_device_release(dev);
        CHECKF(atomic_load(&f.live_blocks) == 0 && atomic_load(&f.live_bytes) == 0,
               "k=%ld (%d threads): %ld blocks, %lld bytes not given back", k, threads, atomic_load(&f.live_blocks),
               (long long)atomic_load(&f.live_bytes));
        if (k > 100000) {
            CHECK(!"allocation count does not converge");
            break;
        }
    }
    return refused_rounds;
}

int main(void) {
    /* past PAR_MIN (65536), so two threads take the parallel gather, binning and partition too */
    mesh = test_mesh_soup(70000, 0.01f, 7);
    for (int i = 0; i < 8; i++) {
        spheres[4 * i + 0] = 0.1f * (float)i, spheres[4 * i + 1] = 2.0f, spheres[4 * i + 2] = 0.5f;
        spheres[4 * i + 3] = 0.04f;
    }
    for (int i = 0; i < 3; i++) balls[i] = (ball){{-3.0f - (float)i, 0, 0}, 0.2f};
    rp_device *ref_dev = rp_device_new(&(rp_device_desc){.threads = 1});
    rp_error err;
    rp_scene *ref = make_scene(ref_dev, &err);
    CHECK(ref && rp_scene_commit(ref) == RP_ERROR_NONE);
    uint64_t expect = ref ? answers(ref) : 0;
    rp_scene_release(ref);
    rp_device_release(ref_dev);
    for (int mode = 0; mode < 2; mode++)
        for (int threads = 1; threads <= 2; threads++) {
            int rounds = sweep(threads, mode == 1, expect);
            printf("%d threads, %s: %d rounds with a refused allocation, each cleaned up\n", threads,
                   mode ? "the k-th allocation refused" : "allocations from the k-th on refused", rounds);
            CHECK(rounds > 5);
        }
    CHECKF(atomic_load(&size_mismatches) == 0, "%ld frees passed another size than the block's",
           atomic_load(&size_mismatches));
    test_mesh_free(&mesh);
    return RP_TEST_END();
}
