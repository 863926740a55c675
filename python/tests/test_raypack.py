"""pytest tests of the raypack Python package (run by CTest through run_ctest.py)."""
import os
import threading
import time

import numpy as np
import pytest

import raypack

SCENES = os.environ.get("RP_SCENES", os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "scenes"))


def scene_path(name):
    p = os.path.join(SCENES, name)
    if not os.path.exists(p):
        pytest.fail(f"shared scene {p} missing")
    return p


def quad():
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    i = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    return raypack.Scene(v, i)


def brute_force(v, tris, o, d):
    """Closest t per ray (Moller-Trumbore in float64), inf on a miss."""
    p0, p1, p2 = v[tris[:, 0]].astype(np.float64), v[tris[:, 1]].astype(np.float64), v[tris[:, 2]].astype(np.float64)
    e1, e2 = p1 - p0, p2 - p0
    best = np.full(len(o), np.inf)
    prim = np.full(len(o), -1)
    for k in range(len(o)):
        dk, ok_ = d[k].astype(np.float64), o[k].astype(np.float64)
        pv = np.cross(dk, e2)
        det = np.einsum("ij,ij->i", e1, pv)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = ok_ - p0
            u = np.einsum("ij,ij->i", tv, pv) * inv
            qv = np.cross(tv, e1)
            w = (qv @ dk) * inv
            t = np.einsum("ij,ij->i", e2, qv) * inv
        good = (np.abs(det) > 1e-12) & (u >= 0) & (w >= 0) & (u + w <= 1) & (t >= 0)
        if good.any():
            j = np.argmin(np.where(good, t, np.inf))
            best[k], prim[k] = t[j], j
    return best, prim


def test_quad_hits_and_misses():
    s = quad()
    o = np.array([[0.25, 0.5, -5], [3, 0, -5], [-0.5, -0.5, -5]], np.float32)
    d = np.array([[0, 0, 1]] * 3, np.float32)
    h = s.intersect(o, d)
    assert h["t"].dtype == np.float32 and h["geom_id"].dtype == np.int32 and h["Ng"].shape == (3, 3)
    assert h["t"][0] == pytest.approx(5.0) and h["geom_id"][0] == 0 and h["prim_id"][0] == 1
    # miss: t inf, ids -1, u v Ng zero (embreex's conventions)
    assert np.isinf(h["t"][1]) and h["geom_id"][1] == -1 and h["prim_id"][1] == -1
    assert h["u"][1] == 0 and h["v"][1] == 0 and not h["Ng"][1].any()
    assert h["prim_id"][2] == 0
    # barycentrics reproduce the hit point: p = (1-u-v) v0 + u v1 + v v2 of triangle (0, 2, 3)
    v = np.array([[-1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    u_, v_ = h["u"][0], h["v"][0]
    p = (1 - u_ - v_) * v[0] + u_ * v[1] + v_ * v[2]
    assert p == pytest.approx([0.25, 0.5, 0], abs=1e-5)
    # Ng faces (v1 - v0) x (v2 - v0) = +z, not normalized
    assert h["Ng"][0][2] > 0 and h["Ng"][0][0] == pytest.approx(0, abs=1e-6)


def test_tnear_tfar_and_occluded():
    s = quad()
    o = np.array([[0, 0, -5]] * 4, np.float32)
    d = np.array([[0, 0, 1]] * 4, np.float32)
    h = s.intersect(o, d, tnear=np.array([0, 6, 0, 0], np.float32), tfar=np.array([np.inf, np.inf, 4, 5.5], np.float32))
    assert list(np.isfinite(h["t"])) == [True, False, False, True]
    assert list(s.occluded(o, d, tfar=np.array([10, 4, 5.5, 1], np.float32))) == [True, False, True, False]
    assert s.occluded(o, -d).tolist() == [False] * 4


def test_random_mesh_matches_brute_force():
    rng = np.random.default_rng(7)
    v = rng.uniform(-1, 1, (300, 3)).astype(np.float32)
    tris = rng.integers(0, 300, (100, 3)).astype(np.uint32)
    s = raypack.Scene(v, tris)
    o = rng.uniform(-2, 2, (400, 3)).astype(np.float32)
    d = (rng.uniform(-1, 1, (400, 3)) - o * 0.3).astype(np.float32)
    h = s.intersect(o, d)
    t_ref, prim_ref = brute_force(v, tris, o, d)
    hit, hit_ref = np.isfinite(h["t"]), np.isfinite(t_ref)
    assert hit.sum() > 50
    # watertight versus Moller-Trumbore: only grazing rays may disagree
    assert (hit != hit_ref).sum() <= 2
    both = hit & hit_ref
    assert np.allclose(h["t"][both], t_ref[both], rtol=1e-4, atol=1e-5)
    assert (h["prim_id"][both] == prim_ref[both]).mean() > 0.98
    assert (s.occluded(o, d) == hit).all()


def bunny_rays(s, n, seed):
    rng = np.random.default_rng(seed)
    lo, hi = s.bounds
    c, r = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    a = rng.normal(size=(n, 3))
    o = (c + r * a / np.linalg.norm(a, axis=1, keepdims=True)).astype(np.float32)
    target = c + rng.uniform(-0.3, 0.3, (n, 3)) * (hi - lo)
    return o, (target - o).astype(np.float32)


def test_bunny_load_and_trace():
    s = raypack.load(scene_path("stanford_bunny_bun_zipper.ply.gz"))
    assert s.triangle_count == 69451
    o, d = bunny_rays(s, 20000, 1)
    h = s.intersect(o, d)
    hit = np.isfinite(h["t"])
    assert 0.2 < hit.mean() < 0.99
    assert (h["prim_id"][hit] >= 0).all() and (h["prim_id"][hit] < 69451).all()
    assert (s.occluded(o, d) == hit).all()
    # the packet path answers the same
    hc = s.intersect(o, d, coherent=True)
    assert np.array_equal(hc["prim_id"], h["prim_id"]) and np.array_equal(hc["t"], h["t"])
    # hit points lie on the bunny: re-tracing from just before them hits at ~the same distance
    p = o[hit] + h["t"][hit, None] * d[hit]
    back = s.intersect(p - 1e-3 * d[hit], d[hit])
    assert np.allclose(back["t"], 1e-3, atol=1e-3)


def test_threads_and_devices():
    dev = raypack.Device(threads=2)
    assert dev.threads == 2
    s = raypack.load(scene_path("stanford_bunny_bun_zipper.ply.gz"), device=dev)
    o, d = bunny_rays(s, 30000, 2)
    ref = s.intersect(o, d)["prim_id"]
    results = [None] * 4

    def work(k):
        results[k] = s.intersect(o, d)["prim_id"]

    ts = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    assert all(np.array_equal(r, ref) for r in results)
    # same rays on a one-thread device: same answers
    s1 = raypack.load(scene_path("stanford_bunny_bun_zipper.ply.gz"), device=raypack.Device(threads=1))
    assert np.array_equal(s1.intersect(o, d)["prim_id"], ref)


def test_gil_released_while_tracing():
    s = raypack.load(scene_path("stanford_bunny_bun_zipper.ply.gz"))
    o, d = bunny_rays(s, 1_000_000, 3)
    started = threading.Event()

    def work():
        started.set()
        s.intersect(o, d)

    th = threading.Thread(target=work)
    th.start()
    started.wait()
    ticks = 0
    while th.is_alive():  # each sleep gives the GIL up; waking needs it back
        time.sleep(0.001)
        ticks += 1
    th.join()
    # held through the call, the loop would wake only in the few ms of Python before and after it
    assert ticks >= 20, ticks


def test_render():
    s = raypack.load(scene_path("spd_teapot.nff.gz"))
    img = raypack.render(s, 64, 48)
    assert img.shape == (48, 64, 3) and img.dtype == np.float32
    assert np.isfinite(img).all() and img.max() > 0.1
    depth = raypack.render(s, 32, 32, aov="depth")
    assert depth.shape == (32, 32, 1)
    # an explicit camera looking away from everything sees the background only
    lo, hi = s.bounds
    c = (lo + hi) / 2
    away = raypack.render(s, 16, 16, eye=c + (hi - lo) * 2, look=c + (hi - lo) * 4, aov="depth")
    assert np.isinf(away).all()
    # a mesh scene from arrays renders too, its quad filling the middle of the image
    q = raypack.render(quad(), 32, 32, eye=(0, 0, 3), look=(0, 0, 0), aov="depth")
    assert q[16, 16, 0] == pytest.approx(3.0, rel=1e-3) and np.isinf(q[0, 0, 0])


def test_vertex_colors():
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    i = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    c = np.tile(np.float32([1.0, 0.5, 0.25]), (4, 1))
    s = raypack.Scene(v, i, colors=c)
    a = raypack.render(s, 16, 16, eye=(0, 0, 3), look=(0, 0, 0), aov="albedo")
    assert a[8, 8] == pytest.approx([0.8, 0.4, 0.2], rel=1e-5)
    with pytest.raises(ValueError):
        raypack.Scene(v, i, colors=c[:3])
    with pytest.raises(ValueError):
        raypack.Scene(v, i, colors=-c)


def test_gltf():
    s = raypack.load(scene_path("gltf_suzanne/Suzanne.gltf"))
    assert s.triangle_count == 3936
    img = raypack.render(s, 32, 32, eye=(0, 0.5, 4), look=(0, 0, 0), aov="albedo")
    assert img[16, 16].max() > 0


def test_texture_sampler(tmp_path):
    """MTL -clamp on reaches the Python renderer: a quad with uv from -1 to 2 over a red | blue
    texture is red at its left edge and blue at its right, where repeating blends the two."""
    (tmp_path / "rb.ppm").write_text("P3\n2 1\n255\n255 0 0 0 0 255\n")
    edges = {}
    for name, opt in (("clamp", "-clamp on "), ("repeat", "")):
        (tmp_path / f"{name}.mtl").write_text(f"newmtl m\nKd 1 1 1\nmap_Kd {opt}rb.ppm\n")
        (tmp_path / f"{name}.obj").write_text(
            f"mtllib {name}.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt -1 -1\nvt 2 -1\nvt 2 2\nvt -1 2\n"
            "usemtl m\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
        img = raypack.render(raypack.load(str(tmp_path / f"{name}.obj")), 32, 32, eye=(0, 0, 3), look=(0, 0, 0),
                             aov="albedo")
        row = img[16]
        cols = np.nonzero(row.max(axis=1) > 0)[0]
        edges[name] = (row[cols[0]], row[cols[-1]])
    left, right = edges["clamp"]
    assert left == pytest.approx([1, 0, 0], abs=1e-5) and right == pytest.approx([0, 0, 1], abs=1e-5)
    assert edges["repeat"][0][2] > 0.05 and edges["repeat"][1][0] > 0.05


def test_bad_input():
    s = quad()
    with pytest.raises(ValueError):
        s.intersect(np.zeros((3, 2), np.float32), np.zeros((3, 2), np.float32))
    with pytest.raises(ValueError):
        s.intersect(np.zeros((3, 3), np.float32), np.zeros((4, 3), np.float32))
    with pytest.raises(ValueError):
        raypack.Scene(np.zeros((3, 3), np.float32), np.array([[0, 1, 3]], np.uint32))
    with pytest.raises(OSError, match="no_such_scene.obj"):
        raypack.load("/nonexistent/no_such_scene.obj")
    with pytest.raises(ValueError):
        raypack.render(s, 8, 8, eye=(0, 0, 1))
    # a camera with no frame: the image would be NaN
    with pytest.raises(ValueError, match="look-at point"):
        raypack.render(s, 8, 8, eye=(0, 0, 1), look=(0, 0, 1))
    with pytest.raises(ValueError, match="parallel"):
        raypack.render(s, 8, 8, eye=(0, 0, 1), look=(0, 0, 0), up=(0, 0, 2))
    with pytest.raises(ValueError, match="fov"):
        raypack.render(s, 8, 8, fov=180)
    assert s.intersect(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32))["t"].shape == (0,)
