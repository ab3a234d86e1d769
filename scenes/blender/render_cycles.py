# Blender Cycles renders of a test scene, one frame or an animated sequence. Run inside Blender:
#   blender -b --factory-startup -noaudio -P render_cycles.py -- SCENE OUT SPP SEED RES [FRAMES]
# SCENE: colonnade, or colonnade-climb (the same arcade, the camera climbing as it slides: motion vectors
# with a vertical part, whose sign tests/blender.rs checks), or study (a room lit by one area light and what
# bounces, the camera dollying in at an angle, a rough-metal head moving across a textured desk; another
# sequence to judge temporal filters by). Add your own scenes beside them. Output: OpenEXR MultiLayer with Combined and the Denoising Data
# passes (Denoising Albedo/Normal/Depth) plus Normal, Depth and Position, as a Blender user writes them.
# With FRAMES > 1 the scene is animated (camera and one object move), OUT is a folder, frames are written as
# OUT/frame_0001.exr ... with the Vector (motion) pass, and each frame has its own noise (animated seed).
import bpy, sys, math
argv = sys.argv[sys.argv.index('--') + 1:]
scene_name, out, spp, seed, res = argv[0], argv[1], int(argv[2]), int(argv[3]), int(argv[4])
frames = int(argv[5]) if len(argv) > 5 else 1
bpy.ops.wm.read_factory_settings(use_empty=True)
sc = bpy.context.scene
sc.render.engine = 'CYCLES'
sc.cycles.device = 'CPU'
sc.cycles.samples = spp
sc.cycles.use_adaptive_sampling = False
sc.cycles.use_denoising = False
sc.cycles.seed = seed
sc.render.resolution_x = sc.render.resolution_y = res
sc.render.resolution_percentage = 100
sc.render.film_transparent = False
vl = sc.view_layers[0]
vl.cycles.denoising_store_passes = True
vl.use_pass_normal = True
vl.use_pass_z = True
if hasattr(vl, 'use_pass_position'):
    vl.use_pass_position = True
sc.render.image_settings.file_format = 'OPEN_EXR_MULTILAYER'
sc.render.image_settings.color_depth = '32'
sc.view_settings.view_transform = 'Standard'


def material(name, color, rough=0.5, metal=0.0, tex=None, scale=10.0, transmission=0.0):
    m = bpy.data.materials.new(name); m.use_nodes = True
    nt = m.node_tree; b = nt.nodes['Principled BSDF']
    b.inputs['Base Color'].default_value = (*color, 1)
    b.inputs['Roughness'].default_value = rough
    b.inputs['Metallic'].default_value = metal
    if transmission:
        b.inputs['Transmission'].default_value = transmission
        b.inputs['IOR'].default_value = 1.45
    if tex == 'checker':
        t = nt.nodes.new('ShaderNodeTexChecker'); t.inputs['Scale'].default_value = scale
        t.inputs['Color1'].default_value = (*color, 1); t.inputs['Color2'].default_value = (color[0] * 0.25, color[1] * 0.25, color[2] * 0.25, 1)
        nt.links.new(t.outputs['Color'], b.inputs['Base Color'])
    elif tex == 'noise':
        t = nt.nodes.new('ShaderNodeTexNoise'); t.inputs['Scale'].default_value = scale; t.inputs['Detail'].default_value = 8
        r = nt.nodes.new('ShaderNodeValToRGB')
        r.color_ramp.elements[0].color = (color[0] * 0.3, color[1] * 0.3, color[2] * 0.3, 1); r.color_ramp.elements[1].color = (*color, 1)
        nt.links.new(t.outputs['Fac'], r.inputs['Fac']); nt.links.new(r.outputs['Color'], b.inputs['Base Color'])
    return m


def box(name, loc, size, mat, rot=0.0):
    bpy.ops.mesh.primitive_cube_add(location=loc, rotation=(0, 0, rot))
    o = bpy.context.object; o.name = name; o.scale = size; o.data.materials.append(mat); return o


def world(color, strength):
    w = bpy.data.worlds.new('w'); sc.world = w; w.use_nodes = True
    bg = w.node_tree.nodes['Background']; bg.inputs['Color'].default_value = (*color, 1); bg.inputs['Strength'].default_value = strength


def camera(loc, look, lens=24):
    bpy.ops.object.camera_add(location=loc); cam = bpy.context.object; cam.data.lens = lens
    d = [look[i] - loc[i] for i in range(3)]
    cam.rotation_euler = (math.atan2(math.hypot(d[0], d[1]), -d[2]), 0, math.atan2(d[1], d[0]) - math.pi / 2)
    sc.camera = cam


if scene_name in ('colonnade', 'colonnade-climb'):
    # a sunlit arcade: a row of pillars close to the camera in front of a textured wall; the camera slides
    # sideways, so the pillars uncover the wall behind them, and a ball rolls across the floor
    box('floor', (0, 0, -0.05), (10, 10, 0.05), material('floor', (0.7, 0.66, 0.58), 0.5, tex='checker', scale=30))
    box('wall', (0, 3.0, 2.0), (10, 0.1, 2.0), material('wall', (0.7, 0.45, 0.3), 0.8, tex='noise', scale=8))
    box('roof', (0, 1.0, 4.05), (10, 2.1, 0.05), material('roof', (0.6, 0.6, 0.6), 0.9))
    pillar = material('pillar', (0.85, 0.83, 0.78), 0.6)
    for i in range(-4, 5):
        bpy.ops.mesh.primitive_cylinder_add(radius=0.18, depth=4.0, location=(i * 1.2, -0.6, 2.0), vertices=48)
        bpy.context.object.data.materials.append(pillar); bpy.ops.object.shade_smooth()
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.45, location=(-1.2, 0.9, 0.45), segments=64, ring_count=32)
    ball = bpy.context.object; ball.data.materials.append(material('ball', (0.9, 0.9, 0.95), 0.05, metal=1.0))
    bpy.ops.object.shade_smooth()
    bpy.ops.object.light_add(type='SUN', location=(0, -6, 8)); sun = bpy.context.object
    sun.data.energy = 3.0; sun.data.angle = math.radians(0.8)
    sun.rotation_euler = (math.radians(50), 0, math.radians(-25))
    world((0.5, 0.65, 1.0), 0.8)
    camera((-0.9, -4.5, 1.4), (0.0, 2.0, 1.0), lens=28)
elif scene_name == 'study':
    # a room lit from above by one area light, most of the light indirect; a wooden-looking desk, a striped
    # rug, a rough-metal head moving across the desk, a glossy vase; the camera dollies in at an angle
    box('floor', (0, 0, -0.05), (4, 4, 0.05), material('floor', (0.55, 0.35, 0.2), 0.4, tex='noise', scale=14))
    box('back', (0, 2.5, 1.5), (4, 0.05, 1.5), material('back', (0.75, 0.75, 0.7), 0.9))
    box('left', (-2.5, 0, 1.5), (0.05, 4, 1.5), material('left', (0.6, 0.2, 0.15), 0.9))
    box('right', (2.5, 0, 1.5), (0.05, 4, 1.5), material('right', (0.2, 0.35, 0.6), 0.9))
    box('ceiling', (0, 0, 3.05), (4, 4, 0.05), material('ceiling', (0.8, 0.8, 0.8), 0.9))
    box('rug', (0.3, 0.6, 0.01), (1.4, 0.9, 0.01), material('rug', (0.8, 0.7, 0.3), 0.9, tex='checker', scale=18))
    box('desk', (0.0, 1.2, 0.75), (1.3, 0.5, 0.04), material('desk', (0.5, 0.3, 0.15), 0.35, tex='noise', scale=30))
    for x in (-1.2, 1.2):
        box('leg', (x, 1.2, 0.37), (0.05, 0.45, 0.37), material('leg', (0.2, 0.2, 0.22), 0.3, metal=1.0))
    bpy.ops.mesh.primitive_monkey_add(size=0.45, location=(-0.9, 1.1, 1.05), rotation=(0, 0, math.radians(200)))
    head = bpy.context.object; head.name = 'Head'
    head.data.materials.append(material('head', (0.95, 0.75, 0.45), 0.3, metal=1.0))
    bpy.ops.object.shade_smooth()
    bpy.ops.mesh.primitive_cylinder_add(radius=0.15, depth=0.5, location=(0.8, 1.3, 1.04), vertices=48)
    bpy.context.object.data.materials.append(material('vase', (0.1, 0.3, 0.25), 0.15))
    bpy.ops.object.shade_smooth()
    bpy.ops.object.light_add(type='AREA', location=(0.6, 0.4, 2.95)); lamp = bpy.context.object
    lamp.data.energy = 250.0; lamp.data.size = 0.6
    world((0.02, 0.02, 0.03), 1.0)
    camera((-1.6, -2.2, 1.6), (0.2, 1.4, 0.9), lens=24)
else:
    raise SystemExit(f'unknown scene {scene_name}')

# the animation: the camera moves 0.06 units a frame (plus the scene's own object), frames 1..FRAMES
MOVES = {'colonnade': ((0.09, 0.0, 0.0), 'Sphere', (0.12, -0.03, 0.0)),
         'colonnade-climb': ((0.06, 0.0, 0.08), 'Sphere', (0.12, -0.03, 0.0)),
         'study': ((0.04, 0.07, -0.01), 'Head', (0.1, 0.0, 0.0))}
if frames > 1:
    cam_step, mover, obj_step = MOVES[scene_name]
    cam = sc.camera; obj = bpy.data.objects[mover]
    sc.frame_start, sc.frame_end = 1, frames
    for f in (1, frames):
        k = f - 1
        base_c, base_o = tuple(cam.location), tuple(obj.location)
        cam.location = [base_c[i] + cam_step[i] * k for i in range(3)]
        obj.location = [base_o[i] + obj_step[i] * k for i in range(3)]
        cam.keyframe_insert('location', frame=f); obj.keyframe_insert('location', frame=f)
        cam.location, obj.location = base_c, base_o
    for o in (cam, obj):
        for fc in o.animation_data.action.fcurves:
            for kp in fc.keyframe_points:
                kp.interpolation = 'LINEAR'
    sc.render.use_motion_blur = False
    vl.use_pass_vector = True
    sc.cycles.use_animated_seed = True
    sc.render.filepath = out.rstrip('/') + '/frame_####'
    bpy.ops.render.render(animation=True)
else:
    sc.render.filepath = out
    bpy.ops.render.render(write_still=True)
