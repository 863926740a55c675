/* BART animation (Lext, Assarsson, Moller 2001): keyframed transforms, animated triangles and the
 * camera path, evaluated at any time.
 *
 * Interpolation follows BART's reference code (after Eberly's Kochanek-Bartels splines), in double:
 * translation and scale are a cubic Hermite spline per key interval with the TCB tangents; rotation
 * is squad between unit quaternions with tangents built from the logs of neighbouring quotients,
 * each key's quaternion negated when it is at an obtuse angle to the one before (as the reference
 * does, in key order; the key after an interval enters its tangent as written). n keys make n - 3
 * intervals from key 1 to key n - 2; outside them the spline holds its end values. Rotation axes
 * are normalized. `tpa` corners move linearly between their keys. The transform of a block is
 * T R S of its channels at the time (BART's GetMatrix), a missing channel the identity. */
#include <math.h>

#include "io/io_internal.h"

/* ---- quaternions (x, y, z, w) ----------------------------------------------------------------- */

typedef struct quat {
    double x, y, z, w;
} quat;

static quat q_axis_angle(const float v[4]) {
    double x = v[0], y = v[1], z = v[2], len = sqrt(x * x + y * y + z * z);
    double half = 0.5 * (double)v[3] * 3.14159265358979323846 / 180.0, s = len > 0.0 ? sin(half) / len : 0.0;
    return (quat){x * s, y * s, z * s, cos(half)};
}

static quat q_mul(quat a, quat b) {
    return (quat){a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y, a.w * b.y + a.y * b.w + a.z * b.x - a.x * b.z,
                  a.w * b.z + a.z * b.w + a.x * b.y - a.y * b.x, a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z};
}

static quat q_conj(quat a) { return (quat){-a.x, -a.y, -a.z, a.w}; }
static double q_dot(quat a, quat b) { return a.x * b.x + a.y * b.y + a.z * b.z + a.w * b.w; }
static quat q_scale(quat a, double s) { return (quat){a.x * s, a.y * s, a.z * s, a.w * s}; }
static quat q_add(quat a, quat b) { return (quat){a.x + b.x, a.y + b.y, a.z + b.z, a.w + b.w}; }

/* log of a unit quaternion: (angle * axis, 0) */
static quat q_log(quat a) {
    if (fabs(a.w) < 1.0) {
        double angle = acos(a.w), sn = sin(angle);
        if (fabs(sn) >= 1e-6) return (quat){a.x * angle / sn, a.y * angle / sn, a.z * angle / sn, 0.0};
    }
    return (quat){a.x, a.y, a.z, 0.0};
}

static quat q_exp(quat a) {
    double angle = sqrt(a.x * a.x + a.y * a.y + a.z * a.z), sn = sin(angle), c = fabs(sn) >= 1e-6 ? sn / angle : 1.0;
    return (quat){a.x * c, a.y * c, a.z * c, cos(angle)};
}

static quat q_slerp(double t, quat p, quat q) {
    double cs = q_dot(p, q);
    cs = cs > 1.0 ? 1.0 : cs < -1.0 ? -1.0 : cs;
    double angle = acos(cs);
    if (fabs(angle) < 1e-6) return p;
    double sn = sin(angle);
    return q_add(q_scale(p, sin((1.0 - t) * angle) / sn), q_scale(q, sin(t * angle) / sn));
}

/* ---- splines ---------------------------------------------------------------------------------- */

/* The interval of the time and the parameter in it: interval i runs from key i + 1 to key i + 2. */
static void spline_interval(const rp_anim_key *k, uint32_t n, double t, uint32_t *seg, double *u) {
    uint32_t polys = n - 3;
    if (!(t > k[1].time)) {
        *seg = 0, *u = 0.0;
    } else if (!(t < k[n - 2].time)) {
        *seg = polys - 1, *u = 1.0;
    } else {
        uint32_t i = 0;
        while (!(t < k[i + 2].time)) i++;
        *seg = i, *u = (t - k[i + 1].time) / ((double)k[i + 2].time - k[i + 1].time);
    }
}

/* The TCB multipliers of BART: outgoing tangent at key i1 and incoming at key i2 of an interval. */
static void tcb_weights(const rp_anim_key *k, uint32_t i0, double w[4]) {
    const rp_anim_key *k0 = &k[i0], *k1 = &k[i0 + 1], *k2 = &k[i0 + 2], *k3 = &k[i0 + 3];
    double dt = (double)k2->time - k1->time, d0 = (double)k2->time - k0->time, d1 = (double)k3->time - k1->time;
    double adj0 = d0 > 0.0 ? 2.0 * dt / d0 : 0.0, adj1 = d1 > 0.0 ? 2.0 * dt / d1 : 0.0;
    double t1 = k1->tension, c1 = k1->continuity, b1 = k1->bias, t2 = k2->tension, c2 = k2->continuity, b2 = k2->bias;
    w[0] = 0.5 * adj0 * (1 - t1) * (1 + c1) * (1 + b1); /* out0: weight of P1 - P0 */
    w[1] = 0.5 * adj0 * (1 - t1) * (1 - c1) * (1 - b1); /* out1: of P2 - P1 */
    w[2] = 0.5 * adj1 * (1 - t2) * (1 - c2) * (1 + b2); /* in0: of P2 - P1 */
    w[3] = 0.5 * adj1 * (1 - t2) * (1 + c2) * (1 - b2); /* in1: of P3 - P2 */
}

static void eval_position(const rp_anim_key *k, uint32_t n, double t, double out[3]) {
    uint32_t seg;
    double u, w[4];
    spline_interval(k, n, t, &seg, &u);
    tcb_weights(k, seg, w);
    for (int c = 0; c < 3; c++) {
        double p0 = k[seg].value[c], p1 = k[seg + 1].value[c], p2 = k[seg + 2].value[c], p3 = k[seg + 3].value[c];
        double dp = p2 - p1, tout = w[1] * dp + w[0] * (p1 - p0), tin = w[3] * (p3 - p2) + w[2] * dp;
        double c2 = 3 * dp - 2 * tout - tin, c3 = -2 * dp + tout + tin;
        out[c] = p1 + u * (tout + u * (c2 + u * c3));
    }
}

static quat eval_rotation(const rp_anim_key *k, uint32_t n, double t) {
    uint32_t seg;
    double u, w[4];
    spline_interval(k, n, t, &seg, &u);
    /* keys 2.. are flipped in order to stay within 90 degrees of the previous (flipped) one */
    quat q0 = q_axis_angle(k[0].value), q1 = q_axis_angle(k[1].value), q2, q3;
    for (uint32_t i = 0;; i++) {
        q2 = q_axis_angle(k[i + 2].value);
        if (q_dot(q1, q2) < 0.0) q2 = q_scale(q2, -1.0);
        if (i == seg) break;
        q0 = q1, q1 = q2;
    }
    q3 = q_axis_angle(k[seg + 3].value);
    tcb_weights(k, seg, w);
    quat logdq = q_log(q_mul(q_conj(q1), q2));
    quat tout = q_add(q_scale(logdq, w[1]), q_scale(q_log(q_mul(q_conj(q0), q1)), w[0]));
    quat tin = q_add(q_scale(logdq, w[2]), q_scale(q_log(q_mul(q_conj(q2), q3)), w[3]));
    quat a = q_mul(q1, q_exp(q_scale(q_add(tout, q_scale(logdq, -1.0)), 0.5)));
    quat b = q_mul(q2, q_exp(q_scale(q_add(logdq, q_scale(tin, -1.0)), 0.5)));
    return q_slerp(2.0 * u * (1.0 - u), q_slerp(u, q1, q2), q_slerp(u, a, b));
}

void rp_anim_track_eval(const rp_animation_data *anim, rp_anim_track track, rp_anim_channel channel, float time,
                        float out[4]) {
    bool absent = !anim || track.count < 4 || (size_t)track.first + track.count > anim->key_count;
    if (channel == RP_ANIM_ROT) {
        quat q = absent ? (quat){0, 0, 0, 1} : eval_rotation(anim->keys + track.first, track.count, time);
        double len = sqrt(q_dot(q, q));
        if (len > 0.0) q = q_scale(q, 1.0 / len);
        out[0] = (float)q.x, out[1] = (float)q.y, out[2] = (float)q.z, out[3] = (float)q.w;
        return;
    }
    double p[3] = {0, 0, 0};
    if (absent && channel == RP_ANIM_SCALE) p[0] = p[1] = p[2] = 1.0;
    if (!absent) eval_position(anim->keys + track.first, track.count, time, p);
    out[0] = (float)p[0], out[1] = (float)p[1], out[2] = (float)p[2], out[3] = 0.0f;
}

/* ---- transforms (row-major 3x4, double) ------------------------------------------------------- */

static void m_mul(const double *a, const double *b, double *out) {
    double r[12];
    for (int row = 0; row < 3; row++)
        for (int col = 0; col < 4; col++) {
            double v = a[4 * row] * b[col] + a[4 * row + 1] * b[4 + col] + a[4 * row + 2] * b[8 + col];
            r[4 * row + col] = col == 3 ? v + a[4 * row + 3] : v;
        }
    memcpy(out, r, sizeof r);
}

bool anim_inverse(const double *m, double *out) {
    double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
    double co[9] = {e * i - f * h, c * h - b * i, b * f - c * e, f * g - d * i, a * i - c * g,
                    c * d - a * f, d * h - e * g, b * g - a * h, a * e - b * d};
    double det = a * co[0] + b * co[3] + c * co[6];
    if (det == 0.0 || !isfinite(det)) return false;
    for (int row = 0; row < 3; row++) {
        for (int col = 0; col < 3; col++) out[4 * row + col] = co[3 * row + col] / det;
        out[4 * row + 3] = -(out[4 * row] * m[3] + out[4 * row + 1] * m[7] + out[4 * row + 2] * m[11]);
    }
    return true;
}

/* T R S of a block's channels at time t. */
static void node_keys(const rp_animation_data *a, const rp_anim_node *n, float t, double *out) {
    float tr[4], q[4], sc[4];
    rp_anim_track_eval(a, n->track[RP_ANIM_TRANSL], RP_ANIM_TRANSL, t, tr);
    rp_anim_track_eval(a, n->track[RP_ANIM_ROT], RP_ANIM_ROT, t, q);
    rp_anim_track_eval(a, n->track[RP_ANIM_SCALE], RP_ANIM_SCALE, t, sc);
    double x = q[0], y = q[1], z = q[2], w = q[3];
    double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                   2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                   2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
    for (int row = 0; row < 3; row++) {
        for (int col = 0; col < 3; col++) out[4 * row + col] = r[3 * row + col] * sc[col];
        out[4 * row + 3] = tr[row];
    }
}

static bool node_visible(const rp_animation_data *a, const rp_anim_node *n, float t) {
    bool v = true; /* visible until the first key */
    for (uint32_t i = 0; i < n->vis_count && (size_t)n->vis_first + i < a->vis_count; i++)
        if (t >= a->vis_times[n->vis_first + i]) v = a->vis_values[n->vis_first + i] != 0;
    return v;
}

typedef struct xf_f {
    float m[12], nm[9], scale;
} xf_f;

static void xf_of(const float *m, xf_f *x) {
    memcpy(x->m, m, sizeof x->m);
    float a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
    float co[9] = {e * i - f * h, f * g - d * i, d * h - e * g, c * h - b * i, a * i - c * g,
                   b * g - a * h, b * f - c * e, c * d - a * f, a * e - b * d};
    float det = a * co[0] + b * co[1] + c * co[2], s = det < 0.0f ? -1.0f : 1.0f;
    for (int k = 0; k < 9; k++) x->nm[k] = s * co[k];
    x->scale = fmaxf(sqrtf(a * a + d * d + g * g), fmaxf(sqrtf(b * b + e * e + h * h), sqrtf(c * c + f * f + i * i)));
}

static void xf_pt(const xf_f *x, const float *in, float *out) {
    const float *m = x->m;
    float v[3] = {in[0], in[1], in[2]};
    for (int r = 0; r < 3; r++) out[r] = m[4 * r] * v[0] + m[4 * r + 1] * v[1] + m[4 * r + 2] * v[2] + m[4 * r + 3];
}

static void xf_nrm(const xf_f *x, const float *in, float *out) {
    const float *m = x->nm;
    float v[3] = {in[0], in[1], in[2]};
    for (int r = 0; r < 3; r++) out[r] = m[3 * r] * v[0] + m[3 * r + 1] * v[1] + m[3 * r + 2] * v[2];
    float len = sqrtf(out[0] * out[0] + out[1] * out[1] + out[2] * out[2]);
    if (len > 0.0f) out[0] /= len, out[1] /= len, out[2] /= len;
}

/* ---- the scene at a time ---------------------------------------------------------------------- */

bool rp_scene_data_set_time(rp_scene_data *s, float t) {
    if (!s || !s->animation || !isfinite(t)) return false;
    rp_animation_data *a = s->animation;
    a->time = t;
    xf_f *xf = malloc((a->node_count + 1) * sizeof *xf);
    if (!xf) return false;
    /* parents open before their children, so come first */
    for (size_t i = 0; i < a->node_count; i++) {
        rp_anim_node *n = &a->nodes[i];
        double rest[12], inv[12], k[12], m[12];
        for (int j = 0; j < 12; j++) rest[j] = n->rest[j];
        if (!anim_inverse(rest, inv)) memcpy(inv, rest, sizeof inv); /* refused at load (io_nff.c) */
        node_keys(a, n, t, k);
        m_mul(rest, k, m);
        m_mul(m, inv, m);
        n->visible = node_visible(a, n, t);
        if (n->parent >= 0 && (size_t)n->parent < i) {
            const rp_anim_node *p = &a->nodes[n->parent];
            double pm[12];
            for (int j = 0; j < 12; j++) pm[j] = p->xfm[j];
            m_mul(pm, m, m);
            n->visible = n->visible && p->visible;
        }
        for (int j = 0; j < 12; j++) n->xfm[j] = (float)m[j];
        xf_of(n->xfm, &xf[i]);
    }
    /* tpa corners in rest space, then everything that a block moves */
    for (size_t i = 0; i < a->tpa_count; i++) {
        const rp_anim_tpa *p = &a->tpas[i];
        const float *k = a->tpa_keys + 19 * (size_t)p->first;
        uint32_t j = 0;
        while (j + 1 < p->count && t >= k[19 * (j + 1)]) j++;
        const float *k0 = k + 19 * j, *k1 = j + 1 < p->count ? k0 + 19 : k0;
        float u = k1[0] > k0[0] && t > k0[0] ? (t - k0[0]) / (k1[0] - k0[0]) : 0.0f;
        if (u > 1.0f) u = 1.0f;
        for (int c = 0; c < 3; c++)
            for (int e = 0; e < 3; e++) {
                a->rest_positions[3 * ((size_t)p->vertex + (size_t)c) + (size_t)e] =
                    k0[1 + 6 * c + e] + u * (k1[1 + 6 * c + e] - k0[1 + 6 * c + e]);
                if (a->rest_normals)
                    a->rest_normals[3 * ((size_t)p->normal + (size_t)c) + (size_t)e] =
                        k0[4 + 6 * c + e] + u * (k1[4 + 6 * c + e] - k0[4 + 6 * c + e]);
            }
        if (a->tri_node[p->triangle] < 0)
            for (int c = 0; c < 3; c++) {
                memcpy(s->positions + 3 * ((size_t)p->vertex + (size_t)c), a->rest_positions + 3 * ((size_t)p->vertex + (size_t)c),
                       3 * sizeof(float));
                if (s->normals && a->rest_normals)
                    memcpy(s->normals + 3 * ((size_t)p->normal + (size_t)c), a->rest_normals + 3 * ((size_t)p->normal + (size_t)c),
                           3 * sizeof(float));
            }
    }
    for (size_t i = 0; i < s->vertex_count; i++)
        if (a->vertex_node[i] >= 0) xf_pt(&xf[a->vertex_node[i]], a->rest_positions + 3 * i, s->positions + 3 * i);
    for (size_t i = 0; s->normals && a->rest_normals && i < s->normal_count; i++)
        if (a->normal_node[i] >= 0) xf_nrm(&xf[a->normal_node[i]], a->rest_normals + 3 * i, s->normals + 3 * i);
    for (size_t i = 0; i < s->sphere_count; i++) {
        if (a->sphere_node[i] < 0) continue;
        const xf_f *x = &xf[a->sphere_node[i]];
        xf_pt(x, a->rest_spheres[i].center, s->spheres[i].center);
        s->spheres[i].radius = a->rest_spheres[i].radius * x->scale;
    }
    for (size_t i = 0; i < s->cone_count; i++) {
        if (a->cone_node[i] < 0) continue;
        const xf_f *x = &xf[a->cone_node[i]];
        xf_pt(x, a->rest_cones[i].base, s->cones[i].base);
        xf_pt(x, a->rest_cones[i].apex, s->cones[i].apex);
        s->cones[i].base_radius = a->rest_cones[i].base_radius * x->scale;
        s->cones[i].apex_radius = a->rest_cones[i].apex_radius * x->scale;
    }
    for (size_t i = 0; i < s->light_count; i++)
        if (a->light_node[i] >= 0) xf_pt(&xf[a->light_node[i]], a->rest_lights[i].position, s->lights[i].position);
    free(xf);
    /* BART's GetCamera: eye from the translation; the viewer looks down -z with +y up of the rotation */
    if (a->camera[RP_ANIM_TRANSL].count >= 4 || a->camera[RP_ANIM_ROT].count >= 4) {
        rp_camera_data *c = &s->camera;
        *c = a->rest_camera;
        if (!c->valid) c->fov_deg = 45.0f, c->up[1] = 1.0f, c->look[2] = -1.0f;
        c->valid = true;
        float dir[3] = {c->look[0] - c->eye[0], c->look[1] - c->eye[1], c->look[2] - c->eye[2]};
        if (a->camera[RP_ANIM_TRANSL].count >= 4) {
            float e[4];
            rp_anim_track_eval(a, a->camera[RP_ANIM_TRANSL], RP_ANIM_TRANSL, t, e);
            memcpy(c->eye, e, sizeof c->eye);
        }
        if (a->camera[RP_ANIM_ROT].count >= 4) {
            float q[4];
            rp_anim_track_eval(a, a->camera[RP_ANIM_ROT], RP_ANIM_ROT, t, q);
            float x = q[0], y = q[1], z = q[2], w = q[3];
            dir[0] = -2 * (x * z + w * y), dir[1] = -2 * (y * z - w * x), dir[2] = -(1 - 2 * (x * x + y * y));
            c->up[0] = 2 * (x * y - w * z), c->up[1] = 1 - 2 * (x * x + z * z), c->up[2] = 2 * (y * z + w * x);
        }
        for (int k = 0; k < 3; k++) c->look[k] = c->eye[k] + dir[k];
    }
    return true;
}

float rp_anim_frame_time(const rp_animation_data *a, int frame, int count) {
    if (!a) return 0.0f;
    if (count <= 1) return a->start;
    return a->start + (float)((double)frame * ((double)a->end - a->start) / (count - 1));
}

float rp_scene_data_frame_time(const rp_scene_data *s, int frame) {
    const rp_animation_data *a = s ? s->animation : NULL;
    return rp_anim_frame_time(a, frame, a ? a->frames : 1);
}

bool rp_scene_data_keep_lights(rp_scene_data *s, const uint32_t *keep, size_t count) {
    if (!s || (count && !keep)) return false;
    for (size_t i = 0; i < count; i++)
        if (keep[i] >= s->light_count) return false;
    rp_light_data *l = malloc((count + 1) * sizeof *l), *rl = malloc((count + 1) * sizeof *rl);
    int32_t *ln = malloc((count + 1) * sizeof *ln);
    if (!l || !rl || !ln) {
        free(l), free(rl), free(ln);
        return false;
    }
    rp_animation_data *a = s->animation;
    for (size_t i = 0; i < count; i++) {
        l[i] = s->lights[keep[i]];
        if (a) rl[i] = a->rest_lights[keep[i]], ln[i] = a->light_node[keep[i]];
    }
    free(s->lights);
    s->lights = l;
    s->light_count = count;
    if (a) {
        free(a->rest_lights), free(a->light_node);
        a->rest_lights = rl, a->light_node = ln;
    } else {
        free(rl), free(ln);
    }
    return true;
}

/* ---- load ------------------------------------------------------------------------------------- */

void anim_free(rp_animation_data *a) {
    if (!a) return;
    free(a->nodes), free(a->keys), free(a->vis_times), free(a->vis_values), free(a->tpas), free(a->tpa_keys);
    free(a->tri_node), free(a->sphere_node), free(a->cone_node), free(a->light_node), free(a->vertex_node);
    free(a->normal_node), free(a->tri_tpa), free(a->rest_positions), free(a->rest_normals), free(a->rest_spheres);
    free(a->rest_cones), free(a->rest_lights);
    free(a);
}

static void *dup_array(const void *p, size_t bytes) {
    void *q = malloc(bytes ? bytes : 1);
    if (q && bytes) memcpy(q, p, bytes);
    return q;
}

bool anim_finish(io_ctx *ctx, rp_scene_data *out) {
    rp_animation_data *a = ctx->anim;
    if (!a) return true;
    ctx->anim = NULL;
    a->vertex_node = malloc((out->vertex_count + 1) * sizeof(int32_t));
    a->normal_node = malloc((out->normal_count + 1) * sizeof(int32_t));
    a->tri_tpa = calloc(out->triangle_count + 1, 1);
    a->rest_positions = dup_array(out->positions, out->vertex_count * 3 * sizeof(float));
    a->rest_normals = out->normals ? dup_array(out->normals, out->normal_count * 3 * sizeof(float)) : NULL;
    a->rest_spheres = dup_array(out->spheres, out->sphere_count * sizeof(rp_sphere_data));
    a->rest_cones = dup_array(out->cones, out->cone_count * sizeof(rp_cone_data));
    a->rest_lights = dup_array(out->lights, out->light_count * sizeof(rp_light_data));
    a->rest_camera = out->camera;
    if (!a->vertex_node || !a->normal_node || !a->tri_tpa || !a->rest_positions || (out->normals && !a->rest_normals) ||
        !a->rest_spheres || !a->rest_cones || !a->rest_lights) {
        anim_free(a);
        return false;
    }
    for (size_t i = 0; i < out->vertex_count; i++) a->vertex_node[i] = -1;
    for (size_t i = 0; i < out->normal_count; i++) a->normal_node[i] = -1;
    for (size_t i = 0; i < out->triangle_count; i++) {
        int32_t n = a->tri_node[i];
        if (n < 0) continue;
        for (int j = 0; j < 3; j++) {
            a->vertex_node[out->indices[3 * i + (size_t)j]] = n;
            if (out->normal_indices) a->normal_node[out->normal_indices[3 * i + (size_t)j]] = n;
        }
    }
    for (size_t i = 0; i < a->tpa_count; i++) a->tri_tpa[a->tpas[i].triangle] = 1;
    out->animation = a;
    rp_scene_data_set_time(out, a->start);
    return true;
}
