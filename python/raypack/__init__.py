"""raypack from Python: scenes from numpy arrays or scene files, ray queries and rendering.

    import numpy as np, raypack
    scene = raypack.load("bunny.ply.gz")                       # or raypack.Scene(vertices, indices)
    hits = scene.intersect(origins, directions)                # (N,3) float32 each
    hits["t"], hits["geom_id"], hits["prim_id"], hits["u"], hits["v"], hits["Ng"]
    image = raypack.render(scene, 256, 256)                    # (256, 256, 3) float32, linear

Conventions (those of embreex, which trimesh uses): a ray that hits nothing has t = inf,
geom_id = prim_id = -1 (int32), u = v = 0 and Ng = (0, 0, 0). Ng is the geometric normal, not
normalized, facing the side (v1 - v0) x (v2 - v0) (Embree's). u, v are barycentrics:
p = (1 - u - v) v0 + u v1 + v v2. Rays are traced in [tnear, tfar). A scene made from arrays has
one geometry (geom_id 0); a loaded scene one per kind (triangles, spheres, cones).

The GIL is released while tracing and rendering, which run on the device's threads: other Python
threads keep running, and calls on one device are serialized by a lock.
"""
import os
import threading

import numpy as np

from ._raypack import ffi, lib

__all__ = ["Device", "Scene", "load", "render", "default_device"]

_INTEGRATORS = {"whitted": 0, "eyelight": 1, "aov": 2}
_AOVS = {"depth": 0, "normal": 1, "primid": 2, "albedo": 3}


class Device:
    """A raypack device: its thread pool traces every query on its scenes (threads=0: all cores)."""

    def __init__(self, threads=0):
        self._ptr = lib.rpy_device_new(int(threads))
        if self._ptr == ffi.NULL:
            raise RuntimeError("rp_device_new failed")
        self._lock = threading.Lock()  # rp_device_parallel_for is not reentrant

    @property
    def threads(self):
        return lib.rp_device_thread_count(self._ptr)

    def close(self):
        if self._ptr is not None and self._ptr != ffi.NULL:
            lib.rp_device_release(self._ptr)  # scenes hold their own reference
        self._ptr = None

    def __del__(self):
        self.close()


_default = None
_default_lock = threading.Lock()


def default_device():
    """The device scenes use when none is given (all hardware threads), made on first use."""
    global _default
    with _default_lock:
        if _default is None:
            _default = Device()
        return _default


def _rays(a, name):
    a = np.ascontiguousarray(a, dtype=np.float32)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must be an (N, 3) array, got shape {a.shape}")
    return a


def _per_ray(x, n, name):
    a = np.ascontiguousarray(np.broadcast_to(np.asarray(x, dtype=np.float32), (n,)))
    if a.shape != (n,):
        raise ValueError(f"{name} must be a scalar or an (N,) array")
    return a


def _ptr(ctype, a):
    return ffi.cast(ctype, ffi.from_buffer(a))


class Scene:
    """A committed scene: Scene(vertices, indices) from an (V, 3) float32 and an (T, 3) uint32
    array (copied), or raypack.load(path) for a scene file. colors: an optional (V, 3) array of
    linear RGB vertex colours (finite, >= 0) multiplying the grey (0.8) material's colour."""

    def __init__(self, vertices=None, indices=None, device=None, _ptr_=None, colors=None):
        self.device = device or default_device()
        if _ptr_ is not None:
            self._ptr = _ptr_
            return
        v = np.ascontiguousarray(vertices, dtype=np.float32)
        i = np.asarray(indices)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"vertices must be a (V, 3) array, got shape {v.shape}")
        if i.ndim != 2 or i.shape[1] != 3:
            raise ValueError(f"indices must be a (T, 3) array, got shape {i.shape}")
        if i.size and (i.min() < 0 or i.max() >= len(v)):
            raise ValueError("indices out of range of the vertices")
        i = np.ascontiguousarray(i, dtype=np.uint32)
        c = ffi.NULL
        if colors is not None:
            c = np.ascontiguousarray(colors, dtype=np.float32)
            if c.shape != v.shape:
                raise ValueError(f"colors must be a (V, 3) array like the vertices, got shape {c.shape}")
            if not (np.isfinite(c).all() and (c >= 0).all()):
                raise ValueError("colors must be finite and not negative")
            c = _ptr("float *", c)
        err = ffi.new("char[512]")
        with self.device._lock:
            p = lib.rpy_scene_from_arrays(self.device._ptr, _ptr("float *", v), len(v), _ptr("uint32_t *", i),
                                          len(i), c, err, 512)
        if p == ffi.NULL:
            raise RuntimeError(ffi.string(err).decode(errors="replace") or "scene creation failed")
        self._ptr = p

    @property
    def triangle_count(self):
        return int(lib.rpy_scene_triangle_count(self._ptr))

    @property
    def bounds(self):
        """(lower, upper) corners of the scene's box, float32 (3,) each."""
        lo, hi = np.empty(3, np.float32), np.empty(3, np.float32)
        lib.rpy_scene_bounds(self._ptr, _ptr("float *", lo), _ptr("float *", hi))
        return lo, hi

    def intersect(self, origins, directions, tnear=0.0, tfar=np.inf, coherent=False):
        """Closest hits of N rays: a dict of t (N,), geom_id (N,) int32, prim_id (N,) int32, u (N,),
        v (N,) and Ng (N, 3); misses as the module's docstring says. tnear and tfar are scalars or
        (N,) arrays; coherent=True traces neighbouring rays as SIMD packets (camera-like sets)."""
        o, d = _rays(origins, "origins"), _rays(directions, "directions")
        if o.shape != d.shape:
            raise ValueError("origins and directions differ in shape")
        n = len(o)
        tn, tf = _per_ray(tnear, n, "tnear"), _per_ray(tfar, n, "tfar")
        out = {"t": np.empty(n, np.float32), "geom_id": np.empty(n, np.int32), "prim_id": np.empty(n, np.int32),
               "u": np.empty(n, np.float32), "v": np.empty(n, np.float32), "Ng": np.empty((n, 3), np.float32)}
        with self.device._lock:
            ok = lib.rpy_intersect(self._ptr, _ptr("float *", o), _ptr("float *", d), _ptr("float *", tn),
                              _ptr("float *", tf), n, bool(coherent), _ptr("float *", out["t"]),
                              _ptr("int32_t *", out["geom_id"]), _ptr("int32_t *", out["prim_id"]),
                              _ptr("float *", out["u"]), _ptr("float *", out["v"]), _ptr("float *", out["Ng"]))
        if not ok:
            raise MemoryError("raypack: out of memory while tracing")
        return out

    def occluded(self, origins, directions, tnear=0.0, tfar=np.inf, coherent=False):
        """(N,) bool: whether anything lies on each ray in [tnear, tfar)."""
        o, d = _rays(origins, "origins"), _rays(directions, "directions")
        if o.shape != d.shape:
            raise ValueError("origins and directions differ in shape")
        n = len(o)
        tn, tf = _per_ray(tnear, n, "tnear"), _per_ray(tfar, n, "tfar")
        out = np.empty(n, np.uint8)
        with self.device._lock:
            ok = lib.rpy_occluded(self._ptr, _ptr("float *", o), _ptr("float *", d), _ptr("float *", tn),
                             _ptr("float *", tf), n, bool(coherent), _ptr("uint8_t *", out))
        if not ok:
            raise MemoryError("raypack: out of memory while tracing")
        return out.astype(bool)

    def close(self):
        if getattr(self, "_ptr", None) is not None:
            lib.rpy_scene_free(self._ptr)
            self._ptr = None

    def __del__(self):
        self.close()


def load(path, device=None):
    """Loads a scene file (OBJ, PLY, NFF, AFF, .gz, .tar.gz, glTF and assimp's formats)."""
    device = device or default_device()
    err = ffi.new("char[1024]")
    with device._lock:
        p = lib.rpy_scene_load(device._ptr, os.fsencode(path), err, 1024)
    if p == ffi.NULL:
        raise OSError(ffi.string(err).decode(errors="replace") or f"{path}: cannot load")
    return Scene(device=device, _ptr_=p)


def render(scene, width=512, height=512, eye=None, look=None, up=(0, 1, 0), fov=45.0, spp=1,
           integrator="whitted", aov=None):
    """Renders the scene: an (height, width, 3) float32 array of linear radiance, top row first
    ((height, width, 1) for aov="depth"). Without eye and look, the scene file's camera or one
    framing the scene. integrator: "whitted" or "eyelight"; aov: "depth", "normal", "primid" or
    "albedo" instead."""
    if (eye is None) != (look is None):
        raise ValueError("give both eye and look, or neither")
    if not 0.0 < float(fov) < 180.0:
        raise ValueError(f"fov {fov}: the vertical field of view must be in (0, 180) degrees")
    if eye is not None:
        e, l, u = (np.asarray(x, np.float64).reshape(3) for x in (eye, look, up))
        d = np.float32(l) - np.float32(e)  # in float, as the renderer forms the frame
        if not (np.all(np.isfinite([e, l, u])) and np.all(np.isfinite(d))):
            raise ValueError("eye, look and up must be finite")
        dd, uu, c = float(d @ d), float(u @ u), np.cross(d.astype(np.float64), u)
        if dd == 0.0:
            raise ValueError("the eye is the look-at point (no view direction)")
        if not float(c @ c) > 1e-10 * dd * uu:
            raise ValueError("the up vector is zero or parallel to the view direction")
    integ = _INTEGRATORS["aov"] if aov is not None else _INTEGRATORS[integrator]
    a = _AOVS[aov] if aov is not None else 0
    ch = lib.rpy_render_channels(integ, a)
    px = np.empty((int(height), int(width), ch), np.float32)
    cam = [np.asarray(x if x is not None else (0, 0, 0), np.float32) for x in (eye, look, up)]
    err = ffi.new("char[256]")
    with scene.device._lock:
        ok = lib.rpy_render(scene._ptr, int(width), int(height), int(spp), integ, a, eye is not None,
                            _ptr("float *", cam[0]), _ptr("float *", cam[1]), _ptr("float *", cam[2]),
                            float(fov), _ptr("float *", px), err, 256)
    if not ok:
        raise RuntimeError(ffi.string(err).decode(errors="replace"))
    return px
