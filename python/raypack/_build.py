"""cffi builder (API mode) of raypack._raypack: a small C layer over the shared libraries
libraypack (core), libraypack_io and libraypack_render that moves numpy arrays in and out and
traces on the device's threads. setup.py runs it; the library is found by _find_raypack()."""
import os
import subprocess

from cffi import FFI

HERE = os.path.dirname(os.path.abspath(__file__))

CDEF = """
typedef struct rp_device rp_device;
typedef struct rpy_scene rpy_scene;
rp_device *rpy_device_new(int threads);
void rp_device_release(rp_device *device);
int rp_device_thread_count(const rp_device *device);
rpy_scene *rpy_scene_from_arrays(rp_device *dev, const float *vertices, size_t vertex_count,
                                 const uint32_t *indices, size_t triangle_count, const float *colors,
                                 char *err, size_t err_size);
rpy_scene *rpy_scene_load(rp_device *dev, const char *path, char *err, size_t err_size);
void rpy_scene_free(rpy_scene *s);
size_t rpy_scene_triangle_count(const rpy_scene *s);
void rpy_scene_bounds(const rpy_scene *s, float *lower, float *upper);
int rpy_intersect(rpy_scene *s, const float *org, const float *dir, const float *tnear,
                   const float *tfar, size_t n, int coherent, float *t, int32_t *geom_id,
                   int32_t *prim_id, float *u, float *v, float *ng);
int rpy_occluded(rpy_scene *s, const float *org, const float *dir, const float *tnear,
                  const float *tfar, size_t n, int coherent, uint8_t *out);
int rpy_render(rpy_scene *s, int width, int height, int spp, int integrator, int aov,
               int have_camera, const float *eye, const float *look, const float *up, float fov,
               float *pixels, char *err, size_t err_size);
int rpy_render_channels(int integrator, int aov);
"""

with open(os.path.join(HERE, "_raypack.c")) as f:
    SOURCE = f.read()


def _find_raypack():
    """(include_dirs, library_dirs) of raypack: RAYPACK_PREFIX (an installed prefix), else
    RAYPACK_BUILD_DIR (an in-tree build; headers from the checkout or RAYPACK_INCLUDE_DIR), else the checkout this
    package sits in (build/release), else pkg-config raypack-render."""
    prefix = os.environ.get("RAYPACK_PREFIX")
    if prefix:
        return [os.path.join(prefix, "include")], [os.path.join(prefix, "lib")]
    root = os.path.dirname(os.path.dirname(HERE))
    build = os.environ.get("RAYPACK_BUILD_DIR") or os.path.join(root, "build", "release")
    include = os.environ.get("RAYPACK_INCLUDE_DIR") or os.path.join(root, "include")
    if os.path.exists(os.path.join(build, "libraypack_render.so")):
        return [include], [os.path.abspath(build)]
    try:
        cflags = subprocess.check_output(["pkg-config", "--cflags-only-I", "raypack-render"], text=True).split()
        libs = subprocess.check_output(["pkg-config", "--libs-only-L", "raypack-render"], text=True).split()
        return [c[2:] for c in cflags], [l[2:] for l in libs]
    except (OSError, subprocess.CalledProcessError):
        raise RuntimeError("raypack not found: set RAYPACK_PREFIX (install prefix) or RAYPACK_BUILD_DIR "
                           "(build folder holding libraypack_render.so), or build build/release first")


include_dirs, library_dirs = _find_raypack()
ffibuilder = FFI()
ffibuilder.cdef(CDEF)
ffibuilder.set_source("raypack._raypack", SOURCE, include_dirs=include_dirs, library_dirs=library_dirs,
                      runtime_library_dirs=library_dirs, libraries=["raypack_render", "raypack_io", "raypack", "m"],
                      extra_compile_args=["-std=c11", "-O2"])

if __name__ == "__main__":
    ffibuilder.compile(verbose=True)
