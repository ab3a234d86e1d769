"""Render a small Cycles scene as a filterjit dataset: the noisy render and a
high-sample reference, each an OpenEXR MultiLayer file as Blender writes it
(Combined, Denoising Albedo/Normal/Depth, Normal, Depth, Position passes).

    blender -b --factory-startup -P scenes/blender/render.py -- OUT_DIR [SIZE] [SPP] [REFERENCE_SPP]

Writes OUT_DIR/noisy.exr, OUT_DIR/reference.exr and OUT_DIR/meta.json. Cycles
on the CPU, fixed seed: the same Blender gives the same files. The scene is a
closed room lit only through a slot in its ceiling by a bright emitter, with
a sphere, a box and a textured floor: little direct light and heavy-tailed
indirect light, as real interiors have.
"""

import json
import os
import sys

import bpy

args = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
if not args:
    sys.exit("usage: blender -b --factory-startup -P render.py -- OUT_DIR [SIZE] [SPP] [REFERENCE_SPP]")
out = os.path.abspath(args[0])
size = int(args[1]) if len(args) > 1 else 64
spp = int(args[2]) if len(args) > 2 else 4
reference_spp = int(args[3]) if len(args) > 3 else 1024
os.makedirs(out, exist_ok=True)

# An empty scene (factory startup has a cube, a light and a camera).
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj, do_unlink=True)
scene = bpy.context.scene


def material(name, color, emission=0.0, roughness=0.8, metallic=0.0, checker=False):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nodes = m.node_tree.nodes
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    if emission > 0:
        bsdf.inputs["Emission"].default_value = (1.0, 0.95, 0.85, 1.0)
        bsdf.inputs["Emission Strength"].default_value = emission
    if checker:
        tex = nodes.new("ShaderNodeTexChecker")
        tex.inputs["Scale"].default_value = 8.0
        tex.inputs["Color1"].default_value = (*color, 1.0)
        tex.inputs["Color2"].default_value = (0.1, 0.1, 0.12, 1.0)
        m.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return m


def box(name, location, scale, mat):
    bpy.ops.mesh.primitive_cube_add(location=location)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = scale
    obj.data.materials.append(mat)
    return obj


white = material("white", (0.75, 0.75, 0.72))
red = material("red", (0.7, 0.12, 0.1))
green = material("green", (0.15, 0.6, 0.15))
floor = material("floor", (0.8, 0.7, 0.5), checker=True)
light = material("light", (0.0, 0.0, 0.0), emission=400.0)

# The room: 4 x 4 x 3, walls as thin boxes; the ceiling has a slot above
# which a small emitter sits, so light enters only through the slot.
box("floor", (0, 0, -0.05), (2, 2, 0.05), floor)
box("back", (0, 2.05, 1.5), (2, 0.05, 1.5), white)
box("left", (-2.05, 0, 1.5), (0.05, 2, 1.5), red)
box("right", (2.05, 0, 1.5), (0.05, 2, 1.5), green)
box("front", (0, -4.05, 1.5), (2, 0.05, 1.5), white)
box("ceiling-a", (-1.2, 0, 3.05), (0.8, 2, 0.05), white)
box("ceiling-b", (1.2, 0, 3.05), (0.8, 2, 0.05), white)
box("ceiling-c", (0, 1.2, 3.05), (0.4, 0.8, 0.05), white)
box("ceiling-d", (0, -1.2, 3.05), (0.4, 0.8, 0.05), white)
box("emitter", (0, 0, 3.4), (0.3, 0.3, 0.02), light)
box("emitter-cover", (0, 0, 3.5), (0.6, 0.6, 0.05), white)
box("block", (0.8, 0.6, 0.5), (0.45, 0.45, 0.5), white)
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(-0.8, -0.2, 0.5), segments=48, ring_count=24)
sphere = bpy.context.active_object
sphere.data.materials.append(material("metal", (0.9, 0.8, 0.6), roughness=0.25, metallic=1.0))
bpy.ops.object.shade_smooth()

bpy.ops.object.camera_add(location=(0, -3.8, 1.5), rotation=(1.5708, 0, 0))
scene.camera = bpy.context.active_object
scene.camera.data.lens = 20
scene.world = bpy.data.worlds.new("black")
scene.world.use_nodes = True
scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0

scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.seed = 1
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.cycles.max_bounces = 8
scene.render.resolution_x = size
scene.render.resolution_y = size
scene.render.resolution_percentage = 100
scene.render.film_transparent = False
scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
scene.render.image_settings.color_depth = "32"
scene.render.image_settings.exr_codec = "ZIP"
layer = scene.view_layers[0]
layer.cycles.denoising_store_passes = True
layer.use_pass_normal = True
layer.use_pass_z = True
if hasattr(layer, "use_pass_position"):
    layer.use_pass_position = True


def render(samples, path):
    scene.cycles.samples = samples
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)


render(spp, os.path.join(out, "noisy.exr"))
render(reference_spp, os.path.join(out, "reference.exr"))
with open(os.path.join(out, "meta.json"), "w") as f:
    json.dump({"scene": "cycles-skylight", "spp": spp, "reference_spp": reference_spp, "renderer": bpy.app.version_string}, f)
print(f"wrote {out}/noisy.exr ({spp} spp) and reference.exr ({reference_spp} spp), {size}x{size}")
