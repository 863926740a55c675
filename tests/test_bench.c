// rp-test: labels=bench timeout=600
/* Runs the built `raypack bench` on small scenes, plain, --vs embree and --grid, and checks that it exits 0,
 * that its JSON has the documented keys and that every mode and engine found the same hits. Its
 * speed is not checked: tests do not time. */
#include "rp_test.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdbool.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

/* ---- a small JSON reader (objects, arrays, strings, numbers, literals) -------------------------- */

typedef enum jtype { J_NULL, J_BOOL, J_NUMBER, J_STRING, J_ARRAY, J_OBJECT } jtype;

typedef struct jvalue {
    jtype type;
    double number;
    char *string;          /* J_STRING */
    struct jvalue *items;  /* J_ARRAY / J_OBJECT values */
    char **keys;           /* J_OBJECT keys */
    size_t count;
} jvalue;

typedef struct jparser {
    const char *p;
    int depth;
} jparser;

/* Recursive: containers hold values. */
static bool json_value(jparser *ps, jvalue *out);

/* Skips whitespace. */
static void json_ws(jparser *ps) {
    while (*ps->p == ' ' || *ps->p == '\n' || *ps->p == '\r' || *ps->p == '\t') ps->p++;
}

/* Reads a string literal; \u escapes are kept as '?' (the bench writes none but control chars). */
static bool json_string(jparser *ps, char **out) {
    if (*ps->p != '"') return false;
    ps->p++;
    size_t cap = 16, n = 0;
    char *s = malloc(cap);
    if (!s) return false;
    while (*ps->p && *ps->p != '"') {
        char c = *ps->p++;
        if (c == '\\') {
            c = *ps->p++;
            if (c == 'u') {
                for (int k = 0; k < 4; k++)
                    if (*ps->p) ps->p++;
                c = '?';
            } else if (c == 'n') {
                c = '\n';
            } else if (c == 't') {
                c = '\t';
            } else if (c == '\0') {
                break;
            }
        }
        if (n + 2 > cap) {
            char *t = realloc(s, cap *= 2);
            if (!t) {
                free(s);
                return false;
            }
            s = t;
        }
        s[n++] = c;
    }
    if (*ps->p != '"') {
        free(s);
        return false;
    }
    ps->p++;
    s[n] = '\0';
    *out = s;
    return true;
}

/* Appends a value (and key) to an array or object. */
static bool json_push(jvalue *v, char *key, const jvalue *item) {
    jvalue *items = realloc(v->items, (v->count + 1) * sizeof *items);
    if (!items) return false;
    v->items = items;
    if (v->type == J_OBJECT) {
        char **keys = realloc(v->keys, (v->count + 1) * sizeof *keys);
        if (!keys) return false;
        v->keys = keys;
        v->keys[v->count] = key;
    }
    v->items[v->count++] = *item;
    return true;
}

/* Frees a parsed value and everything below it. */
static void json_free(jvalue *v) {
    free(v->string);
    for (size_t i = 0; i < v->count; i++) {
        json_free(&v->items[i]);
        if (v->keys) free(v->keys[i]);
    }
    free(v->items);
    free(v->keys);
    memset(v, 0, sizeof *v);
}

/* Reads the members of an array or object after its opening bracket. */
static bool json_container(jparser *ps, jvalue *out, bool object) {
    char close = object ? '}' : ']';
    out->type = object ? J_OBJECT : J_ARRAY;
    json_ws(ps);
    if (*ps->p == close) {
        ps->p++;
        return true;
    }
    for (;;) {
        char *key = NULL;
        json_ws(ps);
        if (object) {
            if (!json_string(ps, &key)) return false;
            json_ws(ps);
            if (*ps->p++ != ':') {
                free(key);
                return false;
            }
        }
        jvalue item;
        memset(&item, 0, sizeof item);
        if (!json_value(ps, &item) || !json_push(out, key, &item)) {
            free(key);
            json_free(&item);
            return false;
        }
        json_ws(ps);
        if (*ps->p == ',') {
            ps->p++;
            continue;
        }
        if (*ps->p++ != close) return false;
        return true;
    }
}

/* Reads any value. */
static bool json_value(jparser *ps, jvalue *out) {
    memset(out, 0, sizeof *out);
    if (++ps->depth > 64) return false;
    json_ws(ps);
    bool ok = false;
    char c = *ps->p;
    if (c == '{' || c == '[') {
        ps->p++;
        ok = json_container(ps, out, c == '{');
    } else if (c == '"') {
        out->type = J_STRING;
        ok = json_string(ps, &out->string);
    } else if (strncmp(ps->p, "true", 4) == 0 || strncmp(ps->p, "false", 5) == 0) {
        out->type = J_BOOL;
        out->number = c == 't';
        ps->p += c == 't' ? 4 : 5;
        ok = true;
    } else if (strncmp(ps->p, "null", 4) == 0) {
        ps->p += 4;
        ok = true;
    } else {
        char *end;
        out->type = J_NUMBER;
        out->number = strtod(ps->p, &end);
        ok = end != ps->p;
        ps->p = end;
    }
    ps->depth--;
    return ok;
}

/* Member `key` of an object, or NULL. */
static const jvalue *json_get(const jvalue *v, const char *key) {
    if (!v || v->type != J_OBJECT) return NULL;
    for (size_t i = 0; i < v->count; i++)
        if (strcmp(v->keys[i], key) == 0) return &v->items[i];
    return NULL;
}

/* A number member, or NAN when missing or not a number. */
static double json_num(const jvalue *v, const char *key) {
    const jvalue *m = json_get(v, key);
    return m && m->type == J_NUMBER ? m->number : NAN;
}

/* Parses a whole file; false when it cannot be read or is not one JSON value. */
static bool json_load(const char *path, jvalue *out) {
    FILE *f = fopen(path, "rb");
    if (!f) return false;
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *text = size >= 0 ? malloc((size_t)size + 1) : NULL;
    bool ok = text && fread(text, 1, (size_t)size, f) == (size_t)size;
    fclose(f);
    if (ok) {
        text[size] = '\0';
        jparser ps = {text, 0};
        ok = json_value(&ps, out);
        json_ws(&ps);
        ok = ok && *ps.p == '\0';
        if (!ok) json_free(out);
    }
    free(text);
    return ok;
}

/* ---- running the CLI ---------------------------------------------------------------------------- */

/* The `raypack` binary: next to the tests folder of this build, else a preset build of the source. */
static bool find_cli(char *out, size_t size) {
    char exe[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n > 0) {
        exe[n] = '\0';
        char *slash = strrchr(exe, '/');
        if (slash) {
            *slash = '\0'; /* build/<preset>/tests */
            snprintf(out, size, "%s/../raypack", exe);
            if (access(out, X_OK) == 0) return true;
        }
    }
    const char *src = getenv("RP_SOURCE_DIR");
    const char *presets[] = {"release", "debug", "asan", "bench"};
    for (size_t i = 0; src && i < sizeof presets / sizeof presets[0]; i++) {
        snprintf(out, size, "%s/build/%s/raypack", src, presets[i]);
        if (access(out, X_OK) == 0) return true;
    }
    return false;
}

/* Folder for this test's outputs (RP_TEST_TMP from CTest, else /tmp). */
static const char *tmp_dir(void) {
    const char *dir = getenv("RP_TEST_TMP");
    if (!dir || !*dir) return "/tmp";
    mkdir(dir, 0755);
    return dir;
}

/* Runs a command line, output into log; returns its exit status (-1 if it did not exit). */
static int run(const char *cmd, const char *log) {
    char full[4096];
    snprintf(full, sizeof full, "%s > '%s' 2>&1", cmd, log);
    int st = system(full);
    if (st == -1 || !WIFEXITED(st)) return -1;
    return WEXITSTATUS(st);
}

/* Prints a log file (when a check failed, so the reason shows in CTest's output). */
static void dump(const char *log) {
    FILE *f = fopen(log, "r");
    if (!f) return;
    char line[512];
    while (fgets(line, sizeof line, f)) fputs(line, stderr);
    fclose(f);
}

/* True when a line of the log holds text. */
static bool log_contains(const char *log, const char *text) {
    FILE *f = fopen(log, "r");
    if (!f) return false;
    char line[512];
    bool found = false;
    while (!found && fgets(line, sizeof line, f)) found = strstr(line, text) != NULL;
    fclose(f);
    return found;
}

/* True when the log says raypack was built without Embree. */
static bool log_says_no_embree(const char *log) { return log_contains(log, "built without Embree"); }

/* bounce1, bounce2: the path tracer's bounce rays of depth 1 and 2 (bench_path.c) */
static const char *kinds[6] = {"primary", "shadow", "reflection", "diffuse", "bounce1", "bounce2"};

/* Plain bench: every ray set has rays, no mismatches and a positive single-ray median. */
static void check_plain_json(const jvalue *root, const char *what) {
    CHECKF(json_get(root, "scene") && json_get(root, "scene")->type == J_STRING, "%s: scene", what);
    CHECKF(json_num(root, "threads") >= 1, "%s: threads", what);
    const jvalue *build = json_get(root, "build");
    CHECKF(json_num(build, "raypack_ms") >= 0, "%s: build.raypack_ms", what);
    CHECKF(json_num(build, "raypack_bytes") > 0, "%s: build.raypack_bytes", what);
    const jvalue *rays = json_get(root, "rays");
    for (int k = 0; k < 6; k++) {
        const jvalue *r = json_get(rays, kinds[k]);
        CHECKF(r != NULL, "%s: rays.%s", what, kinds[k]);
        CHECKF(json_num(r, "count") > 0 || k == 1, "%s: rays.%s.count", what, kinds[k]);
        CHECKF(json_num(r, "mismatches") == 0, "%s: rays.%s.mismatches", what, kinds[k]);
        const jvalue *single = json_get(json_get(json_get(r, "modes"), "single"), "threads_1");
        CHECKF(json_num(single, "mrays_median") >= 0, "%s: rays.%s.modes.single.threads_1", what,
               kinds[k]);
        CHECKF(json_get(json_get(r, "modes"), "packet16") != NULL, "%s: rays.%s.modes.packet16", what,
               kinds[k]);
    }
}

/* --vs embree: the shape of the issue, and zero mismatches on every set. */
static void check_vs_json(const jvalue *root, const char *what) {
    CHECKF(json_get(root, "scene") && json_get(root, "scene")->type == J_STRING, "%s: scene", what);
    CHECKF(json_num(root, "threads") >= 1, "%s: threads", what);
    const jvalue *build = json_get(root, "build");
    const char *build_keys[] = {"raypack_ms", "embree_ms", "embree_hq_ms", "raypack_bytes",
                                "embree_bytes"};
    for (size_t i = 0; i < sizeof build_keys / sizeof build_keys[0]; i++)
        CHECKF(json_num(build, build_keys[i]) >= 0, "%s: build.%s", what, build_keys[i]);
    const jvalue *rays = json_get(root, "rays");
    for (int k = 0; k < 6; k++) {
        const jvalue *r = json_get(rays, kinds[k]);
        CHECKF(r != NULL, "%s: rays.%s", what, kinds[k]);
        CHECKF(json_num(r, "count") > 0 || k == 1, "%s: rays.%s.count", what, kinds[k]);
        CHECKF(json_num(r, "mismatches") == 0, "%s: rays.%s.mismatches = %g", what, kinds[k],
               json_num(r, "mismatches"));
        const jvalue *rp = json_get(r, "raypack"), *emb = json_get(r, "embree");
        CHECKF(json_get(rp, "mode") && json_get(rp, "mode")->type == J_STRING, "%s: rays.%s.raypack.mode",
               what, kinds[k]);
        CHECKF(json_get(emb, "api") && json_get(emb, "api")->type == J_STRING, "%s: rays.%s.embree.api",
               what, kinds[k]);
        const char *stats[] = {"mrays_median", "mrays_min", "mrays_max"};
        for (int s = 0; s < 3; s++) {
            CHECKF(json_num(rp, stats[s]) >= 0, "%s: rays.%s.raypack.%s", what, kinds[k], stats[s]);
            CHECKF(json_num(emb, stats[s]) >= 0, "%s: rays.%s.embree.%s", what, kinds[k], stats[s]);
        }
        CHECKF(json_num(rp, "mrays_min") <= json_num(rp, "mrays_max"), "%s: rays.%s min <= max", what,
               kinds[k]);
        const jvalue *all = json_get(r, "embree_all");
        /* every Embree API with both context flags on every set (DESIGN.md: Embree at its best) */
        static const char *apis[] = {"1", "4", "8", "16", "1M"}, *flags[] = {"coherent", "incoherent"};
        for (int a = 0; a < 5; a++)
            for (int fl = 0; fl < 2; fl++) {
                char key[64];
                snprintf(key, sizeof key, "%s%s/%s", k == 1 ? "rtcOccluded" : "rtcIntersect", apis[a], flags[fl]);
                CHECKF(json_num(all, key) >= 0, "%s: rays.%s.embree_all.%s", what, kinds[k], key);
            }
        const jvalue *ef = json_get(emb, "flags"), *em = json_get(emb, "mode"), *ea = json_get(emb, "api");
        CHECKF(ef && ef->type == J_STRING && (strcmp(ef->string, "coherent") == 0 || strcmp(ef->string, "incoherent") == 0),
               "%s: rays.%s.embree.flags", what, kinds[k]);
        if (ef && em && ea && ef->type == J_STRING && em->type == J_STRING && ea->type == J_STRING) {
            char key[64];
            snprintf(key, sizeof key, "%s/%s", ea->string, ef->string);
            CHECKF(strcmp(key, em->string) == 0, "%s: rays.%s.embree.mode is api/flags", what, kinds[k]);
        }
        CHECKF(json_num(r, "ratio") >= 0, "%s: rays.%s.ratio", what, kinds[k]);
        /* the best modes timed with the engines' calls skipped */
        const jvalue *h = json_get(r, "harness");
        bool traced = json_num(r, "count") > 0;
        CHECKF(traced ? json_num(h, "raypack_mrays") > 0 && json_num(h, "embree_mrays") > 0
                      : json_num(h, "raypack_mrays") >= 0 && json_num(h, "embree_mrays") >= 0,
               "%s: rays.%s.harness", what, kinds[k]);
        CHECKF(json_num(h, "tracing_ratio") >= 0, "%s: rays.%s.harness.tracing_ratio", what, kinds[k]);
        /* each engine's best is the faster of its two finalists, timed `repeats` times */
        const char *fin[2] = {"raypack_finalists", "embree_finalists"}, *name[2] = {"mode", "mode"};
        const jvalue *best[2] = {rp, emb};
        for (int e = 0; e < 2; e++) {
            const jvalue *fv = json_get(r, fin[e]), *bn = json_get(best[e], name[e]);
            CHECKF(fv && fv->type == J_OBJECT && fv->count == 2, "%s: rays.%s.%s has 2 entries", what, kinds[k],
                   fin[e]);
            if (!fv || fv->type != J_OBJECT || !bn || bn->type != J_STRING) continue;
            bool found = false;
            for (size_t i = 0; i < fv->count; i++) {
                CHECKF(fv->items[i].number <= json_num(best[e], "mrays_median"), "%s: rays.%s.%s.%s above the best",
                       what, kinds[k], fin[e], fv->keys[i]);
                if (strcmp(fv->keys[i], bn->string) != 0) continue;
                found = true;
                CHECKF(fabs(fv->items[i].number - json_num(best[e], "mrays_median")) < 1e-3,
                       "%s: rays.%s.%s: the best's median", what, kinds[k], fin[e]);
            }
            CHECKF(found, "%s: rays.%s: the best (%s) is one of the %s", what, kinds[k], bn->string, fin[e]);
        }
    }
}

/* --grid: every level, recursion type and table 2 entry, with the counters of the counted pass. */
static void check_grid_json(const jvalue *root, const char *what) {
    CHECKF(json_get(root, "scene") && json_get(root, "scene")->type == J_STRING, "%s: scene", what);
    CHECKF(json_num(root, "mismatches") == 0, "%s: mismatches", what);
    const char *levels[] = {"primary", "shadow", "refraction1", "refraction2", "reflection1", "reflection2"};
    const char *counters[] = {"box_tests", "tri_tests", "frustum_box_culls", "frustum_tri_culls"};
    for (size_t l = 0; l < sizeof levels / sizeof levels[0]; l++) {
        const jvalue *lv = json_get(json_get(root, "levels"), levels[l]);
        CHECKF(json_num(lv, "rays") >= 0, "%s: levels.%s.rays", what, levels[l]);
        const jvalue *configs = json_get(lv, "configs");
        CHECKF(configs && configs->count == 42, "%s: levels.%s.configs: 42 of them", what, levels[l]);
        const jvalue *c = json_get(configs, "n16_auto_frustum");
        CHECKF(json_num(c, "seconds_median") >= 0 && json_num(c, "mrays") >= 0, "%s: levels.%s n16_auto_frustum",
               what, levels[l]);
        for (size_t k = 0; k < sizeof counters / sizeof counters[0]; k++)
            CHECKF(json_num(json_get(c, "counters"), counters[k]) >= 0, "%s: levels.%s counters.%s", what,
                   levels[l], counters[k]);
    }
    CHECKF(json_num(json_get(json_get(root, "levels"), "primary"), "rays") > 0, "%s: primary rays", what);
    const char *recursions[] = {"primary", "shadows", "refraction", "reflection"};
    for (int r = 0; r < 4; r++) {
        const jvalue *rec = json_get(json_get(root, "recursion"), recursions[r]);
        const jvalue *configs = json_get(rec, "configs");
        const char *names[] = {"single", "simd", "n4_masked", "n8_ranged_frustum", "n32_partition_frustum",
                               "n16_span_frustum"};
        for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
            CHECKF(json_num(json_get(configs, names[i]), "mrays") >= 0, "%s: recursion.%s.configs.%s.mrays",
                   what, recursions[r], names[i]);
        const jvalue *t2 = json_get(json_get(root, "table2"), recursions[r]);
        CHECKF(json_num(t2, "speedup") >= 0 && json_num(t2, "simd_mrays") >= 0, "%s: table2.%s", what,
               recursions[r]);
        CHECKF(json_get(t2, "best") && json_get(t2, "best")->type == J_STRING, "%s: table2.%s.best", what,
               recursions[r]);
        /* auto against the best other configuration: named configurations, and the ratio of their
         * recursion Mrays/s */
        const jvalue *au = json_get(json_get(root, "auto"), recursions[r]);
        const jvalue *ba = json_get(au, "best_auto"), *bo = json_get(au, "best_other");
        CHECKF(ba && ba->type == J_STRING && strstr(ba->string, "auto") && bo && bo->type == J_STRING &&
                   !strstr(bo->string, "auto"),
               "%s: auto.%s names its configurations", what, recursions[r]);
        if (ba && ba->type == J_STRING && bo && bo->type == J_STRING) {
            double a = json_num(json_get(configs, ba->string), "mrays"), b = json_num(json_get(configs, bo->string), "mrays");
            double ratio = json_num(au, "ratio");
            CHECKF(b > 0 && fabs(ratio - a / b) <= 1e-3 * ratio + 1e-4, "%s: auto.%s.ratio %g, configs give %g / %g",
                   what, recursions[r], ratio, a, b);
            const jvalue *pa = json_get(au, "paired_auto");
            CHECKF(json_num(au, "paired_ratio") > 0 && pa && pa->type == J_STRING && strstr(pa->string, "auto"),
                   "%s: auto.%s.paired_auto, paired_ratio", what, recursions[r]);
            double x = json_num(json_get(au, "same_setting"), "n16_auto_frustum");
            CHECKF(x > 0 && json_get(au, "same_setting")->count == 8, "%s: auto.%s.same_setting", what, recursions[r]);
        }
    }
}

/* A tiny `bench --grid` run: exit status and the JSON's keys, not its speed. */
static void grid_case(const char *cli, const char *scene, int size) {
    char json[1024], log[1024], cmd[3 * PATH_MAX + 256];
    const char *dir = tmp_dir();
    snprintf(json, sizeof json, "%s/bench_grid.json", dir);
    snprintf(log, sizeof log, "%s/bench_grid.log", dir);
    remove(json);
    snprintf(cmd, sizeof cmd, "'%s' bench '%s' --grid --width %d --height %d --repeats 1 --threads 2 --json '%s'",
             cli, scene, size, size, json);
    int rc = run(cmd, log);
    CHECKF(rc == 0, "grid: `%s` exited with %d", cmd, rc);
    jvalue root;
    bool parsed = json_load(json, &root);
    CHECKF(parsed, "grid: %s is not valid JSON", json);
    if (parsed) {
        check_grid_json(&root, "grid");
        json_free(&root);
    }
    if (rc != 0 || !parsed) dump(log);
}

/* Runs one bench and checks its exit status and JSON; false when Embree was asked for and is absent. */
static bool bench_case(const char *cli, const char *scene, const char *name, bool vs, int size) {
    char json[1024], log[1024], cmd[4096];
    const char *dir = tmp_dir();
    snprintf(json, sizeof json, "%s/bench_%s.json", dir, name);
    snprintf(log, sizeof log, "%s/bench_%s.log", dir, name);
    remove(json);
    snprintf(cmd, sizeof cmd,
             "'%s' bench %s%s%s --width %d --height %d --repeats 1 --warmup 0 --threads 2%s --json '%s'",
             cli, scene ? "'" : "", scene ? scene : "", scene ? "'" : "", size, size,
             vs ? " --vs embree" : "", json);
    int rc = run(cmd, log);
    if (vs && rc != 0 && log_says_no_embree(log)) {
        printf("%s: raypack was built without Embree, --vs embree skipped\n", name);
        return false;
    }
    CHECKF(rc == 0, "%s: `%s` exited with %d", name, cmd, rc);
    jvalue root;
    bool parsed = json_load(json, &root);
    CHECKF(parsed, "%s: %s is not valid JSON", name, json);
    if (parsed) {
        if (vs)
            check_vs_json(&root, name);
        else
            check_plain_json(&root, name);
        json_free(&root);
    }
    if (rc != 0 || !parsed) dump(log);
    return true;
}

/* --bad-rays: every mode is checked on the sets with NaN/Inf/degenerate rays mixed in (the bench
 * exits 1 when a bad ray does not miss or a good one loses its hit) and both are timed. */
static void bad_rays_case(const char *cli, const char *scene, int size) {
    char json[1024], log[1024], cmd[8192];
    snprintf(json, sizeof json, "%s/bench_bad_rays.json", tmp_dir());
    snprintf(log, sizeof log, "%s/bench_bad_rays.log", tmp_dir());
    remove(json);
    snprintf(cmd, sizeof cmd,
             "'%s' bench '%s' --width %d --height %d --repeats 1 --warmup 0 --threads 2 --bad-rays 0.5 --json '%s'",
             cli, scene, size, size, json);
    int rc = run(cmd, log);
    CHECKF(rc == 0, "bad rays: `%s` exited with %d", cmd, rc);
    jvalue root;
    bool parsed = json_load(json, &root);
    CHECKF(parsed, "bad rays: %s is not valid JSON", json);
    if (parsed) {
        check_plain_json(&root, "bad rays");
        const jvalue *sets = json_get(json_get(&root, "bad_rays"), "sets");
        for (int k = 0; k < 4; k++) {
            const jvalue *s = json_get(sets, kinds[k]);
            CHECKF(json_num(s, "bad") > 0 || k == 1, "bad rays: bad_rays.sets.%s.bad", kinds[k]);
            const jvalue *m = json_get(json_get(s, "modes"), "n16_auto_frustum");
            CHECKF((json_num(m, "finite_mrays") > 0 && json_num(m, "mixed_mrays") > 0) || k == 1,
                   "bad rays: bad_rays.sets.%s.modes.n16_auto_frustum", kinds[k]);
        }
        json_free(&root);
    }
    if (rc != 0 || !parsed) dump(log);
}

/* --engine cuda: on a GPU every kernel's hits equal raypack's single rays on every set (exit 0,
 * JSON); without a GPU the GPU layout is still made from the committed scene before the bench says
 * there is no device (exit 1); without nvcc at build time it is a usage error (exit 2). */
static void cuda_case(const char *cli, const char *scene, int size) {
    char json[1024], log[1024], cmd[8192];
    snprintf(json, sizeof json, "%s/bench_cuda.json", tmp_dir());
    snprintf(log, sizeof log, "%s/bench_cuda.log", tmp_dir());
    remove(json);
    snprintf(cmd, sizeof cmd, "'%s' bench '%s' --engine cuda --width %d --height %d --repeats 1 --json '%s'", cli,
             scene, size, size, json);
    int rc = run(cmd, log);
    if (log_contains(log, "built without CUDA")) {
        CHECKF(rc == 2, "cuda: `%s` exited with %d", cmd, rc);
        return;
    }
    if (log_contains(log, "no CUDA device found")) {
        CHECKF(rc == 1 && log_contains(log, "the GPU layout was made"), "cuda: `%s` exited with %d", cmd, rc);
        if (rc != 1) dump(log);
        return;
    }
    CHECKF(rc == 0, "cuda: `%s` exited with %d", cmd, rc);
    jvalue root;
    bool parsed = rc == 0 && json_load(json, &root);
    CHECKF(parsed, "cuda: %s is not valid JSON", json);
    if (parsed) {
        for (int k = 0; k < 6; k++) {
            const jvalue *set = json_get(json_get(&root, "rays"), kinds[k]);
            CHECKF(json_num(set, "count") > 0 && json_num(set, "mismatches") == 0 && json_num(set, "bit_mismatches") == 0,
                   "cuda: rays.%s", kinds[k]);
            CHECKF(json_num(json_get(json_get(set, "kernels"), "simple"), "mrays") > 0, "cuda: rays.%s.kernels.simple",
                   kinds[k]);
        }
        json_free(&root);
    }
    if (rc != 0 || !parsed) dump(log);
}

/* True when two files hold the same bytes. */
static bool same_bytes(const char *a, const char *b) {
    FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
    bool same = fa && fb;
    for (int ca = 0, cb = 0; same && ca != EOF; same = ca == cb) ca = fgetc(fa), cb = fgetc(fb);
    if (fa) fclose(fa);
    if (fb) fclose(fb);
    return same;
}

/* render --engine cuda: the image (integrator and flags `extra`) is the CPU's `render --anim-flat`
 * with the same flags, byte for byte, on a GPU, or with --cuda-emulate (the kernels' code on the CPU)
 * anywhere nvcc was at build time; without a GPU the GPU run says so (exit 1); without nvcc at build
 * time it is a usage error (exit 2). Not bench's, but it shares its runner and the CUDA cases. */
static void cuda_render_case(const char *cli, const char *scene, const char *integ, const char *extra, bool emulate,
                             int size) {
    char gpu[1024], cpu[1024], log[1024], cmd[8192];
    snprintf(gpu, sizeof gpu, "%s/render_cuda.pfm", tmp_dir());
    snprintf(cpu, sizeof cpu, "%s/render_cpu.pfm", tmp_dir());
    snprintf(log, sizeof log, "%s/render_cuda.log", tmp_dir());
    remove(gpu);
    snprintf(cmd, sizeof cmd, "'%s' render '%s' --engine cuda%s --integrator %s %s --width %d --height %d -o '%s'",
             cli, scene, emulate ? " --cuda-emulate" : "", integ, extra, size, size, gpu);
    int rc = run(cmd, log);
    if (log_contains(log, "built without CUDA")) {
        CHECKF(rc == 2, "cuda render: `%s` exited with %d", cmd, rc);
        return;
    }
    if (!emulate && log_contains(log, "no CUDA device found")) {
        CHECKF(rc == 1, "cuda render: `%s` exited with %d", cmd, rc);
        return;
    }
    CHECKF(rc == 0, "cuda render: `%s` exited with %d", cmd, rc);
    CHECKF(log_contains(log, emulate ? "rays traced on CPU (the CUDA kernels' code" : "rays traced on"),
           "cuda render: `%s` does not say where its rays were traced", cmd);
    snprintf(cmd, sizeof cmd, "'%s' render '%s' --anim-flat --integrator %s %s --width %d --height %d -o '%s' -q", cli,
             scene, integ, extra, size, size, cpu);
    CHECKF(run(cmd, log) == 0, "cuda render: `%s` failed", cmd);
    CHECKF(same_bytes(gpu, cpu), "cuda render: %s (%s) differs from the CPU's %s", gpu, integ, cpu);
}

/* A scene with an alpha-tested quad (MTL map_d of a PPM checker: its red channel below 0.5 cuts)
 * between a wall and an area light, for --engine cuda's cutouts; its path in out. */
static bool write_cutout_scene(char *out, size_t size) {
    char path[1024];
    snprintf(path, sizeof path, "%s/cut_holes.ppm", tmp_dir());
    FILE *f = fopen(path, "wb");
    if (!f) return false;
    fprintf(f, "P3\n4 4\n255\n");
    for (int y = 0; y < 4; y++)
        for (int x = 0; x < 4; x++) fprintf(f, "%d 0 0\n", (x + y) % 2 ? 255 : 0);
    fclose(f);
    snprintf(path, sizeof path, "%s/cut.mtl", tmp_dir());
    if (!(f = fopen(path, "w"))) return false;
    fprintf(f, "newmtl wall\nKd 0.8 0.8 0.8\nnewmtl leaf\nKd 0.8 0.1 0.1\nmap_d cut_holes.ppm\nnewmtl lamp\nKd 0 0 0\nKe 40 40 40\n");
    fclose(f);
    snprintf(out, size, "%s/cut.obj", tmp_dir());
    if (!(f = fopen(out, "w"))) return false;
    fprintf(f, "mtllib cut.mtl\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
               "v -3 -3 0\nv 3 -3 0\nv 3 3 0\nv -3 3 0\nusemtl wall\nf 1/1 2/2 3/3 4/4\n"
               "v -0.82 -1 0.93\nv 0.82 -1 2.07\nv 0.82 1 2.07\nv -0.82 1 0.93\nusemtl leaf\nf 5/1 6/2 7/3 8/4\n"
               "v -4.4 1.6 5\nv -3.6 1.6 5\nv -3.6 2.4 5\nv -4.4 2.4 5\nusemtl lamp\nf 12 11 10 9\n");
    fclose(f);
    return true;
}

int main(void) {
    char cli[PATH_MAX + 64];
    if (!find_cli(cli, sizeof cli)) {
        fprintf(stderr, "raypack binary not found next to this test or under $RP_SOURCE_DIR/build\n");
        CHECK(0);
        return RP_TEST_END();
    }
    printf("cli: %s\n", cli);
    bool small = rp_test_sanitized();
    int size = small ? 32 : 128;
    char cornell_buf[1024], teapot_buf[1024];
    const char *cornell = rp_test_scene("cornell_box/cornell_box.obj", cornell_buf, sizeof cornell_buf);
    const char *teapot = rp_test_scene("spd_teapot.nff.gz", teapot_buf, sizeof teapot_buf);
    char museum_buf[1024];
    const char *museum = rp_test_scene("bart_museum5.tar.gz", museum_buf, sizeof museum_buf);
    CHECK(cornell != NULL);
    CHECK(teapot != NULL);

    /* The generated scene of `make bench`, and scenes with (teapot) and without (Cornell) a camera. */
    bench_case(cli, NULL, "default", false, small ? 16 : 64);
    if (cornell) bench_case(cli, cornell, "cornell", false, size);
    if (cornell && bench_case(cli, cornell, "cornell_vs_embree", true, size) && teapot)
        bench_case(cli, teapot, "teapot_vs_embree", true, size);

    if (cornell) grid_case(cli, cornell, small ? 16 : 48);
    if (cornell) bad_rays_case(cli, cornell, small ? 32 : 64);
    if (cornell) cuda_case(cli, cornell, small ? 32 : 64);
    if (cornell) {
        int cs = small ? 24 : 64;
        cuda_render_case(cli, cornell, "eyelight", "", false, small ? 32 : 96);
        cuda_render_case(cli, cornell, "whitted", "--spp 2", false, cs);
        cuda_render_case(cli, cornell, "path", "--spp 2 --max-depth 3", false, cs);
        cuda_render_case(cli, cornell, "eyelight", "", true, cs);
        cuda_render_case(cli, cornell, "whitted", "--spp 2", true, cs);
        cuda_render_case(cli, cornell, "path", "--spp 2 --max-depth 3", true, cs);
        cuda_render_case(cli, cornell, "direct", "", true, cs);
        cuda_render_case(cli, cornell, "ao", "", true, cs);
        /* eye light of 3 samples a pixel through the stream tracer (it was refused) */
        cuda_render_case(cli, cornell, "eyelight", "--spp 3", true, cs);
        cuda_render_case(cli, cornell, "eyelight", "--spp 3", false, cs);
    }
    /* eye light through a medium: composited as the CPU does (the GPU's batch had shaded the bare
     * surfaces behind the cloud, a different image) */
    char cloud_buf[1024];
    const char *cloud = rp_test_scene("volume_wdas_cloud/wdas_cloud_sixteenth.vdb", cloud_buf, sizeof cloud_buf);
    if (cloud) cuda_render_case(cli, cloud, "eyelight", "", true, small ? 16 : 32);
    /* cut-out surfaces: the GPU's hits passed on the CPU by alpha.c's fix-up (stream tracer, eye
     * light too), the CPU's image byte for byte */
    char cut[1024];
    if (write_cutout_scene(cut, sizeof cut)) {
        int cs = small ? 24 : 48;
        const char *view = "--eye 0,0,9 --look 0,0,0 --fov 45";
        char extra[256];
        cuda_render_case(cli, cut, "eyelight", view, true, cs);
        snprintf(extra, sizeof extra, "%s --spp 2", view);
        cuda_render_case(cli, cut, "whitted", extra, true, cs);
        cuda_render_case(cli, cut, "path", extra, true, cs);
        cuda_render_case(cli, cut, "ao", extra, true, cs);
    } else {
        CHECK(0);
    }
    /* the museum's spheres and cones (and its instances, flattened) are traced on the CPU beside
     * the GPU's triangles: still the CPU's image, byte for byte */
    if (museum) {
        int ms = small ? 24 : 64;
        cuda_render_case(cli, museum, "eyelight", "", true, ms);
        cuda_render_case(cli, museum, "whitted", "", true, ms);
        cuda_render_case(cli, museum, "path", "--spp 2 --max-depth 3", true, ms);
        cuda_render_case(cli, museum, "whitted", "", false, ms);
    }

    /* Usage errors and missing files fail. */
    char cmd[sizeof cli + 128], log[1024];
    snprintf(log, sizeof log, "%s/bench_errors.log", tmp_dir());
    snprintf(cmd, sizeof cmd, "'%s' bench --no-such-flag", cli);
    CHECK(run(cmd, log) != 0);
    snprintf(cmd, sizeof cmd, "'%s' bench --threads 0", cli);
    CHECK(run(cmd, log) != 0);
    snprintf(cmd, sizeof cmd, "'%s' bench --vs nothing", cli);
    CHECK(run(cmd, log) != 0);
    snprintf(cmd, sizeof cmd, "'%s' bench --grid --vs embree", cli);
    CHECK(run(cmd, log) != 0);
    snprintf(cmd, sizeof cmd, "'%s' bench --bad-rays 0 --width 8 --height 8", cli);
    CHECK(run(cmd, log) == 2);
    snprintf(cmd, sizeof cmd, "'%s' bench --bad-rays 1.5 --width 8 --height 8", cli);
    CHECK(run(cmd, log) == 2);
    snprintf(cmd, sizeof cmd, "'%s' bench /no/such/scene.obj --width 8 --height 8", cli);
    CHECK(run(cmd, log) != 0);
    return RP_TEST_END();
}
