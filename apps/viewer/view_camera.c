/* The viewer's camera: fly (WASD/QE), mouse look, orbit about a picked point. Everything turns about
 * the scene's up vector and the camera's right axis, so the horizon stays level; the view direction
 * keeps away from up itself, where the right axis would vanish. */
#include "viewer.h"

#include <math.h>

typedef struct vec {
    float x, y, z;
} vec;

static vec load(const float *p) { return (vec){p[0], p[1], p[2]}; }
static void store(float *p, vec v) {
    p[0] = v.x;
    p[1] = v.y;
    p[2] = v.z;
}
static vec add(vec a, vec b) { return (vec){a.x + b.x, a.y + b.y, a.z + b.z}; }
static vec sub(vec a, vec b) { return (vec){a.x - b.x, a.y - b.y, a.z - b.z}; }
static vec scale(vec a, float s) { return (vec){a.x * s, a.y * s, a.z * s}; }
static float dot(vec a, vec b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static vec cross(vec a, vec b) { return (vec){a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
static float length(vec a) { return sqrtf(dot(a, a)); }
static vec normalize(vec a) {
    float l = length(a);
    return l > 0.0f ? scale(a, 1.0f / l) : a;
}

/* Rodrigues' rotation of v about the unit axis k by angle a. */
static vec rotate(vec v, vec k, float a) {
    float c = cosf(a), s = sinf(a);
    return add(add(scale(v, c), scale(cross(k, v), s)), scale(k, dot(k, v) * (1.0f - c)));
}

/* The camera's frame: forward f, right r, up u (DESIGN.md: r = f x up, u = r x f). */
static void frame(const view_camera *c, vec *f, vec *r, vec *u) {
    *f = normalize(sub(load(c->look), load(c->eye)));
    *r = normalize(cross(*f, load(c->up)));
    *u = cross(*r, *f);
}

void view_camera_move(view_camera *c, float right, float up, float forward) {
    vec f, r, u;
    frame(c, &f, &r, &u);
    vec d = add(add(scale(r, right), scale(normalize(load(c->up)), up)), scale(f, forward));
    store(c->eye, add(load(c->eye), d));
    store(c->look, add(load(c->look), d));
}

/* Pitch limited so that the view direction stays at least ~3 degrees from up and down. */
static float clamp_pitch(vec f, vec up, float pitch) {
    float cur = asinf(fmaxf(-1.0f, fminf(1.0f, dot(f, up))));
    const float lim = 1.52f;
    if (cur + pitch > lim) pitch = lim - cur;
    if (cur + pitch < -lim) pitch = -lim - cur;
    return pitch;
}

void view_camera_turn(view_camera *c, float yaw, float pitch) {
    vec f, r, u, up = normalize(load(c->up));
    frame(c, &f, &r, &u);
    float dist = length(sub(load(c->look), load(c->eye)));
    pitch = clamp_pitch(f, up, pitch);
    f = rotate(rotate(f, r, pitch), up, yaw);
    store(c->look, add(load(c->eye), scale(normalize(f), dist)));
}

void view_camera_orbit(view_camera *c, const float pivot[3], float yaw, float pitch) {
    vec f, r, u, up = normalize(load(c->up)), p = load(pivot);
    frame(c, &f, &r, &u);
    pitch = clamp_pitch(f, up, pitch);
    vec e = sub(load(c->eye), p), l = sub(load(c->look), p);
    e = rotate(rotate(e, r, pitch), up, yaw);
    l = rotate(rotate(l, r, pitch), up, yaw);
    store(c->eye, add(p, e));
    store(c->look, add(p, l));
}

rp_camera view_camera_get(const view_camera *c) {
    rp_camera cam = {.type = RP_CAMERA_PINHOLE};
    for (int k = 0; k < 3; k++) {
        cam.pinhole.eye[k] = c->eye[k];
        cam.pinhole.look[k] = c->look[k];
        cam.pinhole.up[k] = c->up[k];
    }
    cam.pinhole.fov_deg = c->fov_deg;
    return cam;
}

void view_camera_ray(const view_camera *c, int w, int h, float x, float y, float dir[3]) {
    vec f, r, u;
    frame(c, &f, &r, &u);
    float t = tanf(c->fov_deg * 0.5f * 3.14159265f / 180.0f);
    float sx = (2.0f * x / (float)w - 1.0f) * t * ((float)w / (float)h), sy = (1.0f - 2.0f * y / (float)h) * t;
    store(dir, normalize(add(f, add(scale(r, sx), scale(u, sy)))));
}

void view_camera_print(const view_camera *c, FILE *f) {
    /* %.9g: nine significant digits give back the same float */
    fprintf(f, "camera: --eye %.9g,%.9g,%.9g --look %.9g,%.9g,%.9g --up %.9g,%.9g,%.9g --fov %.9g\n",
            (double)c->eye[0], (double)c->eye[1], (double)c->eye[2], (double)c->look[0], (double)c->look[1],
            (double)c->look[2], (double)c->up[0], (double)c->up[1], (double)c->up[2], (double)c->fov_deg);
    fflush(f);
}
