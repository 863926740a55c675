"""Render an OBJ scene with Blender's Cycles as an independent reference for raypack's path tracer.

Run:
  blender -b --factory-startup -noaudio --python tools/cycles/render_ref.py -- \
      SCENE.obj OUT.pfm --width W --height H --spp N \
      --eye X Y Z --look X Y Z --up X Y Z --fov DEG [--max-bounces 32] [--threads 2] [--seed 0]

The scene is built from the OBJ and its MTL here (not Blender's importer), so that the geometry and the
materials are exactly raypack's documented mapping (docs/rendering.md "Radiometry", "Material
mapping"; DESIGN.md "Radiometry" and "Camera"):
  - every face is fanned (0,1,2), (0,2,3), ... as raypack does for convex polygons; a non-convex
    face is an error (raypack ear-clips those);
  - Kd only (Ks 0, no textures, no transmission) -> Diffuse BSDF (Lambert, roughness 0), colour Kd;
    anything else is an error: this script only maps what it can map exactly;
  - MTL Ke (or Ka above 1 with Ke 0, the classic cornell_box's light) -> emitted radiance on the
    FRONT side only (the geometric normal's side, counter-clockwise winding), black on the back,
    added to the light's own Kd diffuse reflection;
  - camera: pinhole at eye looking at look, up, VERTICAL field of view fov, square pixels;
  - pixel = box filter of one pixel, no clamping, no denoising, no adaptive sampling, no light
    threshold, black world; the image is written as linear float radiance, PFM (bottom row first).
"""
import argparse
import math
import os
import struct
import sys
import time

import bpy
from mathutils import Matrix, Vector


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="render_ref.py")
    p.add_argument("scene")
    p.add_argument("output")
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--spp", type=int, default=1024)
    p.add_argument("--eye", type=float, nargs=3, required=True)
    p.add_argument("--look", type=float, nargs=3, required=True)
    p.add_argument("--up", type=float, nargs=3, required=True)
    p.add_argument("--fov", type=float, required=True, help="vertical field of view, degrees")
    p.add_argument("--max-bounces", type=int, default=32)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    return p.parse_args(argv)


def fail(msg):
    sys.stderr.write("render_ref.py: %s\n" % msg)
    sys.exit(2)


def parse_mtl(path):
    mats, cur = {}, None
    with open(path, "r", encoding="utf-8", errors="replace") as f:
        for line in f:
            t = line.split("#", 1)[0].split()
            if not t:
                continue
            k = t[0]
            if k == "newmtl":
                cur = {"Kd": (0.0, 0.0, 0.0), "Ks": (0.0, 0.0, 0.0), "Ke": (0.0, 0.0, 0.0),
                       "Ka": (0.0, 0.0, 0.0), "d": 1.0, "illum": 2, "other": []}
                mats[" ".join(t[1:])] = cur
            elif cur is None:
                continue
            elif k in ("Kd", "Ks", "Ke", "Ka", "Tf"):
                v = tuple(float(x) for x in t[1:4])
                if len(v) == 1:
                    v = (v[0],) * 3
                cur[k] = v
            elif k == "d":
                cur["d"] = float(t[1])
            elif k == "Tr":
                cur["d"] = 1.0 - float(t[1])
            elif k == "illum":
                cur["illum"] = int(t[1])
            elif k.startswith("map_") or k in ("bump", "norm", "disp", "refl"):
                cur["other"].append(k)
    return mats


def parse_obj(path):
    verts, tris, tri_mat, mat_names = [], [], [], []
    mats, cur = {}, -1
    seen, dropped = set(), 0
    base = os.path.dirname(path)
    with open(path, "r", encoding="utf-8", errors="replace") as f:
        for line in f:
            t = line.split("#", 1)[0].split()
            if not t:
                continue
            k = t[0]
            if k == "v":
                verts.append(tuple(float(x) for x in t[1:4]))
            elif k == "mtllib":
                mats.update(parse_mtl(os.path.join(base, " ".join(t[1:]))))
            elif k == "usemtl":
                name = " ".join(t[1:])
                if name not in mat_names:
                    mat_names.append(name)
                cur = mat_names.index(name)
            elif k == "f":
                idx = []
                for tok in t[1:]:
                    i = int(tok.split("/")[0])
                    idx.append(i - 1 if i > 0 else len(verts) + i)
                check_convex([verts[i] for i in idx], line)
                for j in range(1, len(idx) - 1):
                    tri = (idx[0], idx[j], idx[j + 1])
                    key = tuple(sorted(verts[i] for i in tri))
                    if key in seen:
                        # An exact copy of an earlier triangle (same corners). cornell_original's
                        # boxes have one each: their "Bottom Face" lines reuse a side face's
                        # vertices. To raypack the copy is the same surface; Cycles' bounce rays
                        # leaving one copy hit the other at distance 0 (it only skips the
                        # triangle they left), which blackens that face. So keep one.
                        dropped += 1
                        continue
                    seen.add(key)
                    tris.append(tri)
                    tri_mat.append(cur)
    if dropped:
        print("render_ref.py: dropped %d triangles that repeat an earlier one's corners" % dropped)
    return verts, tris, tri_mat, mat_names, mats


def check_convex(pts, line):
    """raypack fans convex faces (every turn left or straight in the projection on the Newell
    normal's largest axis) and ear-clips the rest; only the fan is reproduced here."""
    n = len(pts)
    if n <= 3:
        return
    nx = ny = nz = 0.0
    for i in range(n):
        a, b = pts[i], pts[(i + 1) % n]
        nx += (a[1] - b[1]) * (a[2] + b[2])
        ny += (a[2] - b[2]) * (a[0] + b[0])
        nz += (a[0] - b[0]) * (a[1] + b[1])
    ax = max(range(3), key=lambda i: abs((nx, ny, nz)[i]))
    u, v = (ax + 1) % 3, (ax + 2) % 3
    sign = -1.0 if (nx, ny, nz)[ax] < 0 else 1.0
    for i in range(n):
        a, b, c = pts[i], pts[(i + 1) % n], pts[(i + 2) % n]
        cr = (b[u] - a[u]) * (c[v] - a[v]) - (b[v] - a[v]) * (c[u] - a[u])
        if sign * cr < 0:
            fail("non-convex face (raypack ear-clips it; not reproduced here): " + line.strip())


def make_material(name, m):
    if m is None:
        m = {"Kd": (0.0, 0.0, 0.0), "Ks": (0.0, 0.0, 0.0), "Ke": (0.0, 0.0, 0.0), "Ka": (0.0, 0.0, 0.0),
             "d": 1.0, "illum": 2, "other": []}
    if max(m["Ks"]) > 0 or m["d"] < 1 or m["illum"] > 2 or m["other"]:
        fail("material %s is not Lambert + emission (Ks %s, d %g, illum %d, %s): not mapped" %
             (name, m["Ks"], m["d"], m["illum"], m["other"]))
    kd = tuple(min(max(x, 0.0), 1.0) for x in m["Kd"])
    ke = m["Ke"]
    if max(ke) <= 0 and max(m["Ka"]) > 1:
        ke = m["Ka"]  # docs/rendering.md: MTL Ka above 1 with Ke 0 is emission Ka
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    for node in list(nt.nodes):
        nt.nodes.remove(node)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    diff = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diff.inputs["Color"].default_value = (kd[0], kd[1], kd[2], 1.0)
    diff.inputs["Roughness"].default_value = 0.0
    if max(ke) > 0:
        # front side only: emission colour Ke where Backfacing is 0, black where it is 1
        geo = nt.nodes.new("ShaderNodeNewGeometry")
        mix = nt.nodes.new("ShaderNodeMixRGB")
        mix.blend_type = "MIX"
        mix.inputs["Color1"].default_value = (ke[0], ke[1], ke[2], 1.0)
        mix.inputs["Color2"].default_value = (0.0, 0.0, 0.0, 1.0)
        nt.links.new(geo.outputs["Backfacing"], mix.inputs["Fac"])
        em = nt.nodes.new("ShaderNodeEmission")
        em.inputs["Strength"].default_value = 1.0
        nt.links.new(mix.outputs["Color"], em.inputs["Color"])
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(diff.outputs["BSDF"], add.inputs[0])
        nt.links.new(em.outputs["Emission"], add.inputs[1])
        nt.links.new(add.outputs["Shader"], out.inputs["Surface"])
    else:
        nt.links.new(diff.outputs["BSDF"], out.inputs["Surface"])
    return mat, kd, ke


def build_scene(args):
    verts, tris, tri_mat, mat_names, mats = parse_obj(args.scene)
    if not tris:
        fail("no faces in " + args.scene)
    mesh = bpy.data.meshes.new("scene")
    mesh.from_pydata(verts, [], tris)
    mesh.update(calc_edges=True)
    # from_pydata keeps the corner order: polygon i is triangle i, its normal from the CCW winding
    if len(mesh.polygons) != len(tris):
        fail("Blender dropped faces (%d of %d kept)" % (len(mesh.polygons), len(tris)))
    for i, poly in enumerate(mesh.polygons):
        if tuple(poly.vertices) != tris[i]:
            fail("Blender reordered triangle %d" % i)
        poly.use_smooth = False
        poly.material_index = max(tri_mat[i], 0)
    names = mat_names or ["default"]
    for name in names:
        mat, kd, ke = make_material(name, mats.get(name))
        mesh.materials.append(mat)
        print("render_ref.py: material %-12s Kd %s emission %s" % (name, kd, ke))
    obj = bpy.data.objects.new("scene", mesh)
    bpy.context.scene.collection.objects.link(obj)
    print("render_ref.py: %d vertices, %d triangles" % (len(verts), len(tris)))


def setup_camera(args):
    eye, look, up = Vector(args.eye), Vector(args.look), Vector(args.up)
    f = (look - eye).normalized()
    r = f.cross(up).normalized()
    u = r.cross(f)
    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "PERSP"
    cam_data.sensor_fit = "VERTICAL"
    cam_data.lens_unit = "FOV"
    cam_data.angle_y = math.radians(args.fov)
    cam_data.shift_x = cam_data.shift_y = 0.0
    cam_data.clip_start = 1e-4
    cam_data.clip_end = 1e6
    cam = bpy.data.objects.new("cam", cam_data)
    # Blender's camera looks down its local -z with +y up and +x right
    m = Matrix.Identity(4)
    for k in range(3):
        m[k][0], m[k][1], m[k][2], m[k][3] = r[k], u[k], -f[k], eye[k]
    cam.matrix_world = m
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam


def setup_render(args):
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    cy = sc.cycles
    cy.device = "CPU"
    cy.samples = args.spp
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    cy.use_preview_denoising = False
    cy.seed = args.seed
    cy.pixel_filter_type = "BOX"
    cy.filter_width = 1.0
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    cy.blur_glossy = 0.0
    cy.light_sampling_threshold = 0.0
    cy.max_bounces = args.max_bounces
    cy.diffuse_bounces = args.max_bounces
    cy.glossy_bounces = args.max_bounces
    cy.transmission_bounces = args.max_bounces
    cy.volume_bounces = 0
    cy.transparent_max_bounces = args.max_bounces
    cy.caustics_reflective = True
    cy.caustics_refractive = True
    cy.use_animated_seed = False
    sc.render.film_transparent = False
    sc.render.resolution_x = args.width
    sc.render.resolution_y = args.height
    sc.render.resolution_percentage = 100
    sc.render.pixel_aspect_x = sc.render.pixel_aspect_y = 1.0
    sc.render.use_border = False
    sc.render.threads_mode = "FIXED"
    sc.render.threads = args.threads
    sc.render.use_persistent_data = False
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.image_settings.exr_codec = "ZIP"
    sc.render.image_settings.color_mode = "RGBA"
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 0.0
    sc.world = world


def write_pfm(path, w, h, rgba):
    # Blender's pixels are bottom row first, as PFM's
    with open(path, "wb") as f:
        f.write(b"PF\n%d %d\n-1.0\n" % (w, h))
        vals = []
        for i in range(w * h):
            vals.extend(rgba[4 * i:4 * i + 3])
        f.write(struct.pack("<%df" % len(vals), *vals))


def main():
    args = parse_args()
    for scn in list(bpy.data.scenes)[1:]:
        bpy.data.scenes.remove(scn)
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o, do_unlink=True)
    build_scene(args)
    setup_camera(args)
    setup_render(args)
    exr = os.path.splitext(os.path.abspath(args.output))[0] + ".cycles.exr"
    bpy.context.scene.render.filepath = exr
    t0 = time.time()
    bpy.ops.render.render(write_still=True)
    dt = time.time() - t0
    img = bpy.data.images.load(exr)
    img.colorspace_settings.name = "Linear"
    w, h = img.size
    px = list(img.pixels)
    write_pfm(args.output, w, h, px)
    print("render_ref.py: Blender %s, %dx%d, %d spp, %.1f s render, wrote %s (and %s)" %
          (bpy.app.version_string, w, h, args.spp, dt, args.output, exr))


main()
