"""Render the DESIGN.md sphere in Blender (Cycles, CPU) with an exported gonio material.

Run by tests/export/test_blender.py in a Python that has ``bpy`` (a separate process: bpy pins
NumPy < 2, which gonio's JAX cannot share), as

    python blender_scene.py SIZE SAMPLES LX LY LZ MATERIAL.py OUT.npy [MATERIAL.py OUT.npy ...]

(or ``blender -b --python blender_scene.py -- ARGS``), one render per material file.

Scene: unit sphere (subdivided icosphere, smooth normals) at the origin; orthographic camera on
+z looking down -z covering [-1, 1]^2 (image x right, y up); one sun light of irradiance 1 W/m^2
arriving from direction (LX, LY, LZ), angle 0 (a delta light); black world; box pixel filter one
pixel wide (the pixel-area average); denoiser off; linear float output saved as (H, W, 3) .npy.
"""

import math
import sys

import bpy
import numpy as np
from mathutils import Vector

argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
size, samples = int(argv[0]), int(argv[1])
light = Vector([float(x) for x in argv[2:5]]).normalized()
jobs = list(zip(argv[5::2], argv[6::2], strict=True))

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene

bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=7, radius=1.0)
sphere = bpy.context.active_object
bpy.ops.object.shade_smooth()

cam_data = bpy.data.cameras.new("cam")
cam_data.type = "ORTHO"
cam_data.ortho_scale = 2.0
cam = bpy.data.objects.new("cam", cam_data)
cam.location = (0.0, 0.0, 5.0)
scene.collection.objects.link(cam)
scene.camera = cam

sun_data = bpy.data.lights.new("sun", "SUN")
sun_data.energy = 1.0  # W/m^2 on a surface facing it
sun_data.angle = 0.0
sun = bpy.data.objects.new("sun", sun_data)
sun.rotation_euler = light.to_track_quat("Z", "Y").to_euler()  # emits along its local -Z
scene.collection.objects.link(sun)

world = bpy.data.worlds.new("black")
world.color = (0.0, 0.0, 0.0)
if world.node_tree is not None and "Background" in world.node_tree.nodes:
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
scene.world = world

scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
scene.cycles.max_bounces = 0
scene.cycles.pixel_filter_type = "BOX"
scene.cycles.filter_width = 1.0
scene.cycles.seed = 1
scene.render.resolution_x = size
scene.render.resolution_y = size
scene.render.resolution_percentage = 100
scene.view_settings.view_transform = "Standard"
scene.view_settings.look = "None"
scene.view_settings.exposure = 0.0
scene.view_settings.gamma = 1.0
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"

for material_py, out in jobs:
    # The exported script, run as blender --python would run it: it builds the material.
    namespace = {"__name__": "__main__"}
    with open(material_py) as fh:
        exec(compile(fh.read(), material_py, "exec"), namespace)
    sphere.data.materials.clear()
    sphere.data.materials.append(namespace["material"])
    scene.render.filepath = out + ".exr"
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(out + ".exr")
    px = np.array(img.pixels[:], dtype=np.float32).reshape(size, size, 4)[::-1, :, :3]
    np.save(out, px)
    bpy.data.images.remove(img)
    print("gonio-blender-scene:", out, size, "px,", samples, "spp;", math.fsum(px.ravel()))
