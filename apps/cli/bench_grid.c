/* `raypack bench SCENE --grid`: the experiment grid of Overbeck, Ramamoorthi and Mark 2008, sec. 5.
 * Masked, ranged, partition, span and auto traversal x 4x4..32x32 packets x frusta off and on, and single
 * and SIMD rays as baselines, on four kinds of ray recursion: primary rays; primary rays and
 * point-light shadows; 2-deep refraction with every surface refractive (ior 1.5, refraction only,
 * as sec. 5.1); 2-bounce reflection with every surface a mirror. The bench makes the rays itself,
 * level by level from single-ray hits (no renderer), checks every configuration's hits against
 * them, then times each level; a recursion type's time is the sum of its levels' median times. */
#include "bench.h"
#include "cli.h"
#include <raypack_io.h>

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Levels of rays; a recursion type is a list of them (the primary level serves all four). */
enum {
    GRID_PRIMARY,
    GRID_SHADOW,
    GRID_REFRACT1,
    GRID_REFRACT2,
    GRID_REFLECT1,
    GRID_REFLECT2,
    GRID_LEVELS
};
static const char *const grid_level_names[GRID_LEVELS] = {"primary",     "shadow",      "refraction1",
                                                         "refraction2", "reflection1", "reflection2"};

enum { GRID_RECURSIONS = 4, GRID_MAX_DEPTH = 3 };
static const char *const grid_recursion_names[GRID_RECURSIONS] = {"primary", "shadows", "refraction",
                                                                  "reflection"};
/* Levels of each recursion type, -1 terminated. */
static const int grid_recursion_levels[GRID_RECURSIONS][GRID_MAX_DEPTH + 1] = {
    {GRID_PRIMARY, -1, -1, -1},
    {GRID_PRIMARY, GRID_SHADOW, -1, -1},
    {GRID_PRIMARY, GRID_REFRACT1, GRID_REFRACT2, -1},
    {GRID_PRIMARY, GRID_REFLECT1, GRID_REFLECT2, -1},
};

/* Single and SIMD rays, then 5 algorithms x 4 sizes x frustum off/on. */
enum { GRID_ALGORITHMS = 5, GRID_SIZES = 4, GRID_CONFIGS = 2 + GRID_ALGORITHMS * GRID_SIZES * 2 };
static const rp_traversal grid_algorithms[GRID_ALGORITHMS] = {RP_TRAVERSAL_MASKED, RP_TRAVERSAL_RANGED,
                                                              RP_TRAVERSAL_PARTITION, RP_TRAVERSAL_SPAN,
                                                              RP_TRAVERSAL_AUTO};
static const char *const grid_algorithm_names[GRID_ALGORITHMS] = {"masked", "ranged", "partition", "span", "auto"};
static const uint32_t grid_sizes[GRID_SIZES] = {4, 8, 16, 32};

/* One column of the grid. */
typedef struct grid_config {
    char name[32];
    rp_traversal traversal;
    uint32_t n;
    bool frustum;
} grid_config;

/* One level of rays with its single-ray hits, and what each configuration did on it. */
typedef struct grid_level {
    bench_rays *set;
    bench_hits *ref;
    rp_frustum_kind frustum;   /* the level's frustum when frusta are on */
    bench_stat seconds[GRID_CONFIGS];
    rp_counters_n counters[GRID_CONFIGS];
} grid_level;

typedef struct grid_run {
    bench_ctx *ctx;
    grid_config configs[GRID_CONFIGS];
    grid_level levels[GRID_LEVELS];
    bench_rays own_sets[GRID_LEVELS];  /* the levels bench_make_ray_sets does not make */
    bench_hits own_refs[GRID_LEVELS];
    bench_n_engine engine;             /* the configuration being traced */
    double paired[GRID_RECURSIONS];    /* grid_pair: auto in place of the best other, timed in pairs */
    double paired_same[GRID_RECURSIONS][GRID_SIZES * 2]; /* and auto over the best fixed per setting */
} grid_run;

/* The 42 configurations: baselines first, then by algorithm, size and frustum. */
static void grid_make_configs(grid_config *c) {
    c[0] = (grid_config){"single", RP_TRAVERSAL_SINGLE, 16, false};
    c[1] = (grid_config){"simd", RP_TRAVERSAL_SIMD, 16, false};
    int i = 2;
    for (int a = 0; a < GRID_ALGORITHMS; a++)
        for (int s = 0; s < GRID_SIZES; s++)
            for (int f = 0; f < 2; f++, i++) {
                c[i].traversal = grid_algorithms[a];
                c[i].n = grid_sizes[s];
                c[i].frustum = f != 0;
                snprintf(c[i].name, sizeof c[i].name, "n%u_%s%s", grid_sizes[s], grid_algorithm_names[a],
                         f ? "_frustum" : "");
            }
}

/* Index of a configuration, -1 when absent. */
static int grid_find(const grid_run *g, rp_traversal traversal, uint32_t n, bool frustum) {
    for (int i = 0; i < GRID_CONFIGS; i++)
        if (g->configs[i].traversal == traversal && g->configs[i].n == n && g->configs[i].frustum == frustum)
            return i;
    return -1;
}

/* The mode tracing level l with configuration c (through g->engine, valid until the next call). */
static bench_mode grid_mode(grid_run *g, int l, int c, bool count) {
    const grid_config *cfg = &g->configs[c];
    const grid_level *lv = &g->levels[l];
    bench_n_engine_init(&g->engine, g->ctx->scene, cfg->n, cfg->traversal,
                        cfg->frustum ? lv->frustum : RP_FRUSTUM_NONE, g->ctx->light);
    g->engine.count = count;
    bench_mode m = {cfg->name, lv->set->occlusion ? bench_trace_n_occluded : bench_trace_n_intersect,
                    &g->engine};
    return m;
}

/* Makes a level from the hits of its parent, with its single-ray hits. */
static bool grid_make_level(grid_run *g, int l, int parent, bench_next how) {
    bench_ctx *ctx = g->ctx;
    bench_rays *set = &g->own_sets[l];
    bench_hits *ref = &g->own_refs[l];
    if (!bench_rays_alloc(set, BENCH_REFLECTION, ctx->opts.width, ctx->opts.height) ||
        !bench_hits_alloc(ref, set->slots))
        return false;
    bench_make_next(ctx, g->levels[parent].set, g->levels[parent].ref, set, how);
    bench_mode single[1];
    bench_raypack_modes(ctx, set, single, 1);
    bench_trace_set(ctx, ctx->opts.threads, &single[0], set, ref);
    g->levels[l] = (grid_level){.set = set, .ref = ref, .frustum = RP_FRUSTUM_SECONDARY};
    return true;
}

/* Every level: primary, shadow and first reflection from the plain bench's sets, the rest here. */
static bool grid_make_levels(grid_run *g) {
    bench_ctx *ctx = g->ctx;
    if (!bench_make_ray_sets(ctx)) return false;
    g->levels[GRID_PRIMARY] = (grid_level){.set = &ctx->sets[BENCH_PRIMARY], .ref = &ctx->ref[BENCH_PRIMARY],
                                           .frustum = RP_FRUSTUM_PRIMARY};
    g->levels[GRID_SHADOW] = (grid_level){.set = &ctx->sets[BENCH_SHADOW], .ref = &ctx->ref[BENCH_SHADOW],
                                          .frustum = RP_FRUSTUM_SHADOW};
    g->levels[GRID_REFLECT1] = (grid_level){.set = &ctx->sets[BENCH_REFLECTION],
                                            .ref = &ctx->ref[BENCH_REFLECTION], .frustum = RP_FRUSTUM_SECONDARY};
    return grid_make_level(g, GRID_REFLECT2, GRID_REFLECT1, BENCH_NEXT_REFLECT) &&
           grid_make_level(g, GRID_REFRACT1, GRID_PRIMARY, BENCH_NEXT_REFRACT) &&
           grid_make_level(g, GRID_REFRACT2, GRID_REFRACT1, BENCH_NEXT_REFRACT);
}

/* Every configuration on every level against the single-ray hits; false on any mismatch. */
static bool grid_check(grid_run *g, bench_hits *hits) {
    bench_ctx *ctx = g->ctx;
    bool ok = true;
    for (int l = 0; l < GRID_LEVELS; l++) {
        const grid_level *lv = &g->levels[l];
        for (int c = 0; c < GRID_CONFIGS; c++) {
            bench_mode m = grid_mode(g, l, c, false);
            bench_trace_set(ctx, ctx->opts.threads, &m, lv->set, hits);
            bench_diff d = bench_compare(&ctx->mesh, lv->set, lv->ref, hits);
            if (d.total == 0) continue;
            fprintf(stderr,
                    "raypack bench: %s rays: %s disagrees with single rays on %zu of %zu (hit/miss %zu, "
                    "distance %zu, primitive %zu)\n",
                    grid_level_names[l], m.name, d.total, lv->set->count, d.hit_miss, d.distance, d.primitive);
            bench_print_mismatches(&ctx->mesh, lv->set, lv->ref, hits, "single", m.name, 3);
            ok = false;
        }
    }
    return ok;
}

/* The r-th stride coprime to GRID_CONFIGS (1 first): k * stride visits every configuration once. */
static int grid_stride(int r) {
    int s = 0;
    for (int found = -1; found < r % GRID_CONFIGS;) {
        s++;
        int a = s, b = GRID_CONFIGS;
        while (b) {
            int t = a % b;
            a = b, b = t;
        }
        if (a == 1) found++;
    }
    return s;
}

/* Times every configuration on every level: the check pass was the first warm-up, --warmup adds
 * the rest; then `repeats` rounds, configurations taking turns so that drift hits them alike.
 * Then one counted pass each, apart from the timed ones. */
static bool grid_time(grid_run *g, bench_hits *hits) {
    bench_ctx *ctx = g->ctx;
    int reps = ctx->opts.repeats, threads = ctx->opts.threads;
    double *samples = calloc((size_t)reps * GRID_CONFIGS, sizeof *samples);
    if (!samples) return false;
    for (int l = 0; l < GRID_LEVELS; l++) {
        grid_level *lv = &g->levels[l];
        for (int w = 1; w < ctx->opts.warmup; w++)
            for (int c = 0; c < GRID_CONFIGS; c++) {
                bench_mode m = grid_mode(g, l, c, false);
                bench_trace_set(ctx, threads, &m, lv->set, hits);
            }
        for (int r = 0; r < reps; r++)
            for (int k = 0, step = grid_stride(r); k < GRID_CONFIGS; k++) {
                /* each round in another order, so that no configuration always follows the same one */
                int c = (k * step + r) % GRID_CONFIGS;
                bench_mode m = grid_mode(g, l, c, false);
                samples[(size_t)c * (size_t)reps + (size_t)r] = bench_trace_set(ctx, threads, &m, lv->set, hits);
            }
        for (int c = 0; c < GRID_CONFIGS; c++) {
            lv->seconds[c] = bench_stats(samples + (size_t)c * (size_t)reps, reps);
            for (int t = 0; t < ctx->scratch.threads; t++)
                memset(bench_scratch_counters(ctx->scratch.per_thread[t]), 0, sizeof(rp_counters_n));
            bench_mode m = grid_mode(g, l, c, true);
            bench_trace_set(ctx, threads, &m, lv->set, hits);
            memset(&lv->counters[c], 0, sizeof lv->counters[c]);
            for (int t = 0; t < ctx->scratch.threads; t++)
                rp_counters_n_add(&lv->counters[c], bench_scratch_counters(ctx->scratch.per_thread[t]));
        }
    }
    free(samples);
    return true;
}

/* Live rays of a recursion type. */
static size_t grid_rays(const grid_run *g, int r) {
    size_t n = 0;
    for (const int *l = grid_recursion_levels[r]; *l >= 0; l++) n += g->levels[*l].set->count;
    return n;
}

/* Seconds of a recursion type with a configuration: the sum of its levels' medians. */
static double grid_seconds(const grid_run *g, int r, int c) {
    double s = 0.0;
    for (const int *l = grid_recursion_levels[r]; *l >= 0; l++) s += g->levels[*l].seconds[c].median;
    return s;
}

/* Mrays/s of a recursion type with a configuration. */
static double grid_mrays(const grid_run *g, int r, int c) {
    double s = grid_seconds(g, r, c);
    return s > 0.0 ? (double)grid_rays(g, r) / s * 1e-6 : 0.0;
}

/* Table 2 of the paper for one recursion type: the best 16x16 algorithm with frusta on. */
static int grid_best16(const grid_run *g, int r) {
    int best = -1;
    for (int a = 0; a < GRID_ALGORITHMS; a++) {
        int c = grid_find(g, grid_algorithms[a], 16, true);
        if (c >= 0 && (best < 0 || grid_mrays(g, r, c) > grid_mrays(g, r, best))) best = c;
    }
    return best;
}

/* Which configurations a "best of" looks at: the auto ones, or the others (n == 0: all of them,
 * single and SIMD rays included; else masked, ranged and partition at size n, frusta fr). */
static bool grid_pick(const grid_config *k, bool autos, uint32_t n, bool fr) {
    if ((k->traversal == RP_TRAVERSAL_AUTO) != autos) return false;
    if (autos || !n) return true;
    return k->n == n && k->frustum == fr && k->traversal != RP_TRAVERSAL_SINGLE && k->traversal != RP_TRAVERSAL_SIMD;
}

/* The fastest configuration grid_pick takes for a recursion type. */
static int grid_best_of(const grid_run *g, int r, bool autos, uint32_t n, bool fr) {
    int best = -1;
    for (int c = 0; c < GRID_CONFIGS; c++)
        if (grid_pick(&g->configs[c], autos, n, fr) && (best < 0 || grid_mrays(g, r, c) > grid_mrays(g, r, best)))
            best = c;
    return best;
}

/* Mrays/s of configuration a over that of b (0 when b took no time). */
static double grid_ratio(const grid_run *g, int r, int a, int b) {
    double y = grid_mrays(g, r, b);
    return y > 0.0 ? grid_mrays(g, r, a) / y : 0.0;
}

/* Mrays/s of configuration a over b on recursion r, timed head to head: `rounds` rounds, each
 * tracing every level of the recursion with a and with b (which goes first alternates); from the
 * medians of the round totals. t: scratch of 2 * rounds. */
static double grid_pair_one(grid_run *g, bench_hits *hits, int r, int a, int b, int rounds, double *t) {
    const int c[2] = {a, b};
    memset(t, 0, sizeof *t * (size_t)rounds * 2);
    for (int k = 0; k < rounds; k++)
        for (int i = 0; i < 2; i++) {
            int w = (i + k) & 1;
            for (const int *l = grid_recursion_levels[r]; *l >= 0; l++) {
                bench_mode m = grid_mode(g, *l, c[w], false);
                t[w * rounds + k] += bench_trace_set(g->ctx, g->ctx->opts.threads, &m, g->levels[*l].set, hits);
            }
        }
    double ta = bench_stats(t, rounds).median, tb = bench_stats(t + rounds, rounds).median;
    return ta > 0.0 ? tb / ta : 0.0;
}

/* Auto in place of the best configuration that is not auto: auto at its packet size and frustum
 * setting, or the best auto when it is single or SIMD rays. */
static int grid_auto_for(const grid_run *g, int r) {
    const grid_config *b = &g->configs[grid_best_of(g, r, false, 0, false)];
    if (b->traversal == RP_TRAVERSAL_SINGLE || b->traversal == RP_TRAVERSAL_SIMD) return grid_best_of(g, r, true, 0, false);
    return grid_find(g, RP_TRAVERSAL_AUTO, b->n, b->frustum);
}

/* The grid's rounds leave a few percent of drift between configurations, and the best of several
 * configurations is biased upward by it; so auto is timed again head to head against the
 * configuration it is compared with: auto in place of the best other configuration (grid_auto_for),
 * and auto at each packet size and frustum setting against the best fixed algorithm there. */
static bool grid_pair(grid_run *g, bench_hits *hits, int rounds) {
    double *t = calloc((size_t)rounds * 2, sizeof *t);
    if (!t) return false;
    for (int r = 0; r < GRID_RECURSIONS; r++) {
        int best = grid_best_of(g, r, false, 0, false), a = grid_auto_for(g, r);
        g->paired[r] = 0.0;
        for (int s = 0; s < GRID_SIZES; s++)
            for (int f = 0; f < 2; f++) {
                int af = grid_find(g, RP_TRAVERSAL_AUTO, grid_sizes[s], f != 0);
                int bf = grid_best_of(g, r, false, grid_sizes[s], f != 0);
                g->paired_same[r][2 * s + f] = grid_pair_one(g, hits, r, af, bf, rounds, t);
                /* the best other packet configuration is the best fixed one at its setting */
                if (af == a && bf == best) g->paired[r] = g->paired_same[r][2 * s + f];
            }
        if (g->paired[r] == 0.0) g->paired[r] = grid_pair_one(g, hits, r, a, best, rounds, t);
    }
    free(t);
    return true;
}

/* Auto against the best fixed algorithm at each packet size and frustum setting, then the best
 * auto configuration against the best configuration that is not auto (single and SIMD rays too). */
static void grid_print_auto(const grid_run *g) {
    printf("\nauto / best fixed algorithm at the same packet size and frustum setting (+f: frusta on), timed\n"
           "in pairs after the grid\n%-11s",
           "recursion");
    for (int s = 0; s < GRID_SIZES; s++)
        for (int f = 0; f < 2; f++) printf(" %5u%s", grid_sizes[s], f ? "+f" : "  ");
    printf("  best auto / best other (configurations); in pairs: auto in its place\n");
    for (int r = 0; r < GRID_RECURSIONS; r++) {
        printf("%-11s", grid_recursion_names[r]);
        for (int s = 0; s < GRID_SIZES; s++)
            for (int f = 0; f < 2; f++) printf(" %7.2f", g->paired_same[r][2 * s + f]);
        int a = grid_best_of(g, r, true, 0, false), b = grid_best_of(g, r, false, 0, false);
        printf("  %.2f (%s %.2f / %s %.2f); %s %.2f\n", grid_ratio(g, r, a, b), g->configs[a].name,
               grid_mrays(g, r, a), g->configs[b].name, grid_mrays(g, r, b), g->configs[grid_auto_for(g, r)].name,
               g->paired[r]);
    }
}

/* The grid table, then table 2. */
static void grid_print(const grid_run *g) {
    printf("\nlive rays:");
    for (int l = 0; l < GRID_LEVELS; l++) printf(" %s %zu", grid_level_names[l], g->levels[l].set->count);
    printf("\n\n%-22s", "Mrays/s");
    for (int r = 0; r < GRID_RECURSIONS; r++) printf(" %11s", grid_recursion_names[r]);
    printf("\n");
    for (int c = 0; c < GRID_CONFIGS; c++) {
        printf("%-22s", g->configs[c].name);
        for (int r = 0; r < GRID_RECURSIONS; r++) printf(" %11.2f", grid_mrays(g, r, c));
        printf("\n");
    }
    int simd = grid_find(g, RP_TRAVERSAL_SIMD, 16, false);
    printf("\ntable 2: 16x16 packets, best algorithm, frusta on, over single SIMD rays (width %d)\n",
           rp_device_isa(g->ctx->device));
    printf("%-11s %10s %-22s %10s %8s\n", "recursion", "simd", "best 16x16", "Mrays/s", "speedup");
    for (int r = 0; r < GRID_RECURSIONS; r++) {
        int b = grid_best16(g, r);
        double s = grid_mrays(g, r, simd), p = grid_mrays(g, r, b);
        printf("%-11s %10.2f %-22s %10.2f %8.2f\n", grid_recursion_names[r], s, g->configs[b].name, p,
               s > 0.0 ? p / s : 0.0);
    }
    grid_print_auto(g);
}

/* The counters of one configuration on one level, totals (divide by the level's rays for rates). */
static void grid_json_counters(FILE *f, const rp_counters_n *c) {
    fprintf(f,
            "{\"packets\": %llu, \"box_tests\": %llu, \"tri_tests\": %llu, \"frustum_box_tests\": %llu, "
            "\"frustum_box_culls\": %llu, \"frustum_tri_tests\": %llu, \"frustum_tri_culls\": %llu, ",
            (unsigned long long)c->packets, (unsigned long long)c->box_tests, (unsigned long long)c->tri_tests,
            (unsigned long long)c->frustum_box_tests, (unsigned long long)c->frustum_box_culls,
            (unsigned long long)c->frustum_tri_tests, (unsigned long long)c->frustum_tri_culls);
    cli_json_traversal(f, c);
    fputc('}', f);
}

/* --json: levels (per ray type: seconds, Mrays/s, counters), recursion types, table 2. */
static bool grid_write_json(const grid_run *g) {
    const bench_ctx *ctx = g->ctx;
    rp_atomic_file *af;
    FILE *f = bench_json_begin(ctx, &af);
    if (!f) return false;
    fprintf(f, ", \"triangles\": %zu, \"threads\": %d, \"width\": %d, \"height\": %d, \"repeats\": %d, "
               "\"simd_width\": %d, \"isa\": \"%s\", \"mismatches\": 0,\n \"levels\": {",
            ctx->mesh.triangle_count, ctx->opts.threads, ctx->opts.width, ctx->opts.height, ctx->opts.repeats,
            rp_device_isa(ctx->device), cli_isa_name(rp_device_isa(ctx->device)));
    for (int l = 0; l < GRID_LEVELS; l++) {
        const grid_level *lv = &g->levels[l];
        fprintf(f, "%s\n  \"%s\": {\"rays\": %zu, \"configs\": {", l ? "," : "", grid_level_names[l],
                lv->set->count);
        for (int c = 0; c < GRID_CONFIGS; c++) {
            bench_stat s = lv->seconds[c];
            fprintf(f, "%s\n   \"%s\": {\"seconds_median\": %.6f, \"seconds_min\": %.6f, \"seconds_max\": %.6f, "
                       "\"mrays\": %.4f, \"counters\": ",
                    c ? "," : "", g->configs[c].name, s.median, s.min, s.max,
                    s.median > 0.0 ? (double)lv->set->count / s.median * 1e-6 : 0.0);
            grid_json_counters(f, &lv->counters[c]);
            fprintf(f, "}");
        }
        fprintf(f, "}}");
    }
    fprintf(f, "\n },\n \"recursion\": {");
    for (int r = 0; r < GRID_RECURSIONS; r++) {
        fprintf(f, "%s\n  \"%s\": {\"rays\": %zu, \"levels\": [", r ? "," : "", grid_recursion_names[r],
                grid_rays(g, r));
        for (const int *l = grid_recursion_levels[r]; *l >= 0; l++)
            fprintf(f, "%s\"%s\"", l == grid_recursion_levels[r] ? "" : ", ", grid_level_names[*l]);
        fprintf(f, "], \"configs\": {");
        for (int c = 0; c < GRID_CONFIGS; c++)
            fprintf(f, "%s\n   \"%s\": {\"seconds\": %.6f, \"mrays\": %.4f}", c ? "," : "", g->configs[c].name,
                    grid_seconds(g, r, c), grid_mrays(g, r, c));
        fprintf(f, "}}");
    }
    fprintf(f, "\n },\n \"table2\": {");
    int simd = grid_find(g, RP_TRAVERSAL_SIMD, 16, false);
    for (int r = 0; r < GRID_RECURSIONS; r++) {
        int b = grid_best16(g, r);
        double s = grid_mrays(g, r, simd), p = grid_mrays(g, r, b);
        fprintf(f, "%s\n  \"%s\": {\"simd_mrays\": %.4f, \"best\": \"%s\", \"best_mrays\": %.4f, \"speedup\": %.4f}",
                r ? "," : "", grid_recursion_names[r], s, g->configs[b].name, p, s > 0.0 ? p / s : 0.0);
    }
    fprintf(f, "\n },\n \"auto\": {");
    for (int r = 0; r < GRID_RECURSIONS; r++) {
        int a = grid_best_of(g, r, true, 0, false), b = grid_best_of(g, r, false, 0, false);
        fprintf(f,
                "%s\n  \"%s\": {\"best_auto\": \"%s\", \"best_other\": \"%s\", \"ratio\": %.4f, \"paired_auto\": \"%s\", "
                "\"paired_ratio\": %.4f, \"same_setting\": {",
                r ? "," : "", grid_recursion_names[r], g->configs[a].name, g->configs[b].name,
                grid_ratio(g, r, a, b), g->configs[grid_auto_for(g, r)].name, g->paired[r]);
        for (int sz = 0; sz < GRID_SIZES; sz++)
            for (int fr = 0; fr < 2; fr++)
                fprintf(f, "%s\"%s\": %.4f", sz + fr ? ", " : "",
                        g->configs[grid_find(g, RP_TRAVERSAL_AUTO, grid_sizes[sz], fr != 0)].name,
                        g->paired_same[r][2 * sz + fr]);
        fprintf(f, "}}");
    }
    fprintf(f, "\n }\n}\n");
    return bench_json_end(af);
}

int bench_grid(bench_ctx *ctx) {
    double build_ms;
    rp_scene_stats st;
    memset(&st, 0, sizeof st);
    ctx->scene = bench_build_raypack(ctx, &build_ms, &st);
    if (!ctx->scene) return 1;
    grid_run *g = calloc(1, sizeof *g);
    bench_hits hits = {NULL, NULL};
    int rc = 1;
    if (!g) goto done;
    g->ctx = ctx;
    grid_make_configs(g->configs);
    if (!grid_make_levels(g) || !bench_hits_alloc(&hits, ctx->sets[0].slots)) {
        fprintf(stderr, "raypack bench: out of memory\n");
        goto done;
    }
    bench_print_header(ctx);
    printf("build     %.2f ms, %llu triangles, depth %u, SAH %.2f\n", build_ms,
           (unsigned long long)st.triangles, st.depth, st.sah_cost);
    if (!grid_check(g, &hits)) goto done;
    printf("check     %d configurations x %d levels find the single-ray hits on every ray\n", GRID_CONFIGS,
           GRID_LEVELS);
    fflush(stdout);
    if (!grid_time(g, &hits) || !grid_pair(g, &hits, 3 * ctx->opts.repeats + 1)) goto done;
    grid_print(g);
    rc = 0;
    if (ctx->opts.json_path && !grid_write_json(g)) rc = 1;
done:
    bench_hits_free(&hits);
    if (g)
        for (int l = 0; l < GRID_LEVELS; l++) {
            bench_rays_free(&g->own_sets[l]);
            bench_hits_free(&g->own_refs[l]);
        }
    free(g);
    return rc;
}
