/* State shared by the physically based integrators (path.c, instant_radiosity.c, pbr.c). */
#ifndef RP_RENDER_PBR_H
#define RP_RENDER_PBR_H

#include "../render.h"

/* A path being traced: what the next hit's emission and lights are multiplied by. */
typedef struct pbr_path {
    v3 beta;          /* throughput */
    v3 prev;          /* where the ray started (for the light pdf of an emitter hit) */
    float pdf;        /* solid angle pdf of the BSDF sample that made the ray */
    uint32_t pixel;   /* index in the tile */
    int depth;        /* bounces so far */
    bool specular;    /* the ray left a delta lobe (or the camera): emitters count in full */
    render_sampler rng;
} pbr_path;

/* A virtual point light: intensity towards w is power cos(n, w) / pi, or power / (4 pi) when n is 0.
 * An infinite one (from the environment or a directional light) is radiance from direction p
 * over its density: a shading point gathers f cos power from it. */
typedef struct ir_vpl {
    v3 p, n, power;
    bool infinite;
} ir_vpl;

/* What instant radiosity keeps of a primary hit. */
typedef struct ir_point {
    v3 org;           /* the hit point lifted off the surface, where shadow rays start */
    v3 ng, ns, t, b;  /* t, b, ns: the shading frame */
    v3 wo;            /* towards the eye, in the shading frame */
    v3 beta;          /* throughput of the delta chain from the eye to here (1 without one) */
    v3 lambert;       /* beta kd / pi when the BSDF is Lambert (the common case, no eval needed), beta
                       * times bsdf_eval_constant's value for a smooth plastic */
    render_bsdf bsdf;
    bool is_lambert;  /* lambert is the BSDF's value towards every VPL above the surface */
    bool valid;       /* a non-delta surface was hit */
} ir_point;

/* VPLs whose shadow rays instant radiosity decides on (Russian roulette) and traces together. */
#define IR_CHUNK 16
/* Russian roulette's random numbers: render_hash(the pixel sample's PCG key ^ sampler_pcg_dim(IR_RR_DIM
 * + the VPL's index in its set)). */
#define IR_RR_DIM 0x49520000u

/* A set's shadow rays towards IR_CHUNK VPLs (row k: VPL k of the chunk, column: packet lane):
 * direction, tfar, the unoccluded contribution and whether the ray is traced (then: unoccluded). */
typedef struct ir_chunk {
    float dx[IR_CHUNK][64], dy[IR_CHUNK][64], dz[IR_CHUNK][64], tf[IR_CHUNK][64];
    float cr[IR_CHUNK][64], cg[IR_CHUNK][64], cb[IR_CHUNK][64];
    int32_t live[IR_CHUNK][64];
} ir_chunk;

typedef struct pbr_thread {
    rp_rayhit_n prim;       /* the n x n primary packet */
    int32_t *prim_valid;
    rp_auto_tally tally[RP_RAY_KIND_COUNT];
    pbr_path *paths;        /* tile^2 */
    rp_rayhit *bounce;      /* tile^2 */
    rp_ray *shadow;         /* tile^2 */
    v3 *shadow_L;
    uint32_t *shadow_pixel;
    ir_point *points;       /* tile^2 */
    v3 *ir_sum;             /* tile^2: sum of VPL contributions */
    uint16_t *ir_at;        /* (tile / N)^2 x N^2: per block of the tile and set, the pixel (ly tile + lx) */
    rp_rayhit_n vpl_packet; /* a set's shadow rays towards one VPL */
    ir_chunk *chunk;
    rp_rayhit_n rr_packet;  /* a chunk's live shadow rays packed densely (SIMD-ray scenes) */
    int32_t rr_valid[IR_CHUNK * 64];
    uint16_t rr_from[IR_CHUNK * 64]; /* the packed ray's k * 64 + lane in the chunk */
    uint32_t lane[32 * 32]; /* rp_packet_n_index of (i, j) at j * side + i */
} pbr_thread;

typedef struct pbr_frame {
    /* instant radiosity: the VPLs of every sample of the frame, [sample][set][vpl] */
    ir_vpl *vpls;
    int sets, per_set, interleave, side; /* side: rays per packet side of a set in a tile */
    float clamp_d2;                      /* minimum squared distance of the geometry term */
    float rr;                            /* Russian roulette's threshold (ir_roulette); 0: off */
    rp_traversal shadow_traversal;       /* of the shadow packets to VPLs (ir_frame_init) */
    /* full-frame buffers for the discontinuity buffer */
    v3 *albedo, *emit;
    float *raw[3], *normal[3]; /* by axis: the filter's loops read them in vectors */
    float *depth;
    uint8_t *valid;
    void *planes; /* the block that holds them (render_scratch_take) */
} pbr_frame;

float pbr_mis(float a, float b);
rp_query_n_desc pbr_query(const render_frame *f, render_thread *th, rp_ray_kind kind);

/* path.c: one path vertex (path tracing, direct lighting, ambient occlusion): adds the hit's
 * emission (or the environment) to th->accum[3 * st->pixel], queues the light sample's shadow ray
 * in th->pbr->shadow[*nshadow] (its radiance in shadow_L, its pixel in shadow_pixel) and samples
 * the bounce into *next; false when the path ends. The stream tracer shades with it too. */
bool path_vertex(const render_frame *f, render_thread *th, pbr_path *st, const rp_rayhit *rh, rp_rayhit *next,
                 uint32_t *nshadow);
/* Adds c to th->accum's pixel, unless it is not finite. */
void path_add_px(render_thread *th, uint32_t pixel, v3 c);
/* path.c: path tracing, direct lighting and ambient occlusion of one tile (sums into th->accum). */
bool path_tile(const render_frame *f, render_thread *th, int x0, int y0, int x1, int y1);
/* A ray from org along dir with no hit yet (tnear 0, tfar inf). */
static inline void pbr_rayhit_reset(rp_rayhit *rh, v3 org, v3 dir) {
    render_ray_init(&rh->ray, org, dir, INFINITY);
    rh->hit.geom_id = RP_INVALID_ID;
    rh->hit.prim_id = RP_INVALID_ID;
    rh->hit.inst_id = RP_INVALID_ID;
}
/* volume.c, with a participating medium: delta tracking along rh's ray up to its hit; at a real
 * collision the medium vertex (albedo, NEE with ratio tracking, phase sampling into *next, Russian
 * roulette). Returns -1 when the ray got through (shade its hit as usual), 0 when the path ends,
 * 1 when *next holds the bounce. */
int volume_path_vertex(const render_frame *f, render_thread *th, pbr_path *st, const rp_rayhit *rh, rp_rayhit *next,
                       uint32_t *nshadow);
/* Ratio-tracking transmittance of a surface vertex's shadow ray. */
float volume_shadow_transmittance(const render_frame *f, const pbr_path *st, v3 org, v3 dir, float tfar);
/* The medium's opacity 1 - T along a primary ray up to its hit (ray marching, deterministic). */
float volume_primary_opacity(const render_frame *f, const rp_ray *ray);
/* instant_radiosity.c */
bool ir_frame_init(render_frame *f);
bool ir_tile(const render_frame *f, render_thread *th, int x0, int y0, int x1, int y1);
void ir_frame_finish(render_frame *f);

#endif
