"""Denoise a Mitsuba 3 sequence in the same process, frame by frame, with the
history carried from frame to frame (docs/PYTHON.md).

A Cornell box seen by a camera that slides sideways: each frame is rendered at
1 spp with its albedo, normal, position and depth. What a real-time engine's
G-buffer gives beside them, computed here from the ray through each pixel's
centre: the motion vectors as Blender's Vector pass holds them (where the
pixel's surface was in the frame before, minus where it is, in pixels, y
up), and which pixels see an emitter, whose albedo is set to zero (as
Cycles' Denoising Albedo has it: light is not reflected colour, so the
denoiser must not divide or blur it as one). Needs `pip install mitsuba` and
Mitsuba's LLVM variant (Debian: libllvm19).
"""

import numpy as np


def camera_at(mi, k, size):
    """The sensor of frame `k`: the camera slid 0.06 to the right a frame."""
    scene = mi.cornell_box()
    x = 0.06 * k - 0.1
    scene["sensor"]["to_world"] = mi.ScalarTransform4f().look_at(origin=[x, 0, 3.9], target=[x, 0, 0], up=[0, 1, 0])
    scene["sensor"]["film"]["width"] = size
    scene["sensor"]["film"]["height"] = size
    return scene


def centre_hits(mi, scene, size):
    """The first hit of the ray through each pixel's centre: its position and
    whether it is an emitter (a G-buffer's, free of the samples' jitter)."""
    loaded = mi.load_dict(scene)
    sensor = loaded.sensors()[0]
    ys, xs = np.mgrid[0:size, 0:size].astype(np.float32) + 0.5
    uv = mi.Point2f(xs.ravel() / size, ys.ravel() / size)
    ray, _ = sensor.sample_ray(0.0, 0.0, uv, mi.Point2f(0.5, 0.5))
    si = loaded.ray_intersect(ray)
    points = np.stack([np.array(si.p.x), np.array(si.p.y), np.array(si.p.z)], -1)
    emitter = np.array(si.shape.is_emitter(), dtype=bool)
    return points, np.array(si.is_valid(), dtype=bool), emitter.reshape(size, size)


def motion_vectors(mi, scene_before, points, hit, size):
    """Blender's Vector pass X, Y for each pixel: its surface (`points`, the
    centre ray's hits) on the frame before's film minus the pixel's centre,
    y up; 0 where the ray hit nothing."""
    sensor = mi.load_dict(scene_before).sensors()[0]
    it = mi.Interaction3f()
    it.p = mi.Point3f(points[:, 0], points[:, 1], points[:, 2])
    ds, _ = sensor.sample_direction(it, mi.Point2f(0.5, 0.5))
    before = np.stack([np.array(ds.uv.x), np.array(ds.uv.y)], -1).reshape(size, size, 2)
    ys, xs = np.mgrid[0:size, 0:size].astype(np.float32) + 0.5
    motion = np.stack([before[..., 0] - xs, ys - before[..., 1]], -1)
    motion[~hit.reshape(size, size)] = 0.0
    return np.ascontiguousarray(motion, dtype=np.float32)


def render_sequence(mi, frames, size=64, spp=1, reference_spp=256):
    """Each frame's inputs for `filterjit.Denoiser.denoise` and its reference."""
    out = []
    aovs = "albedo:albedo,sh_normal:sh_normal,position:position,depth:depth"
    for k in range(frames):
        scene = camera_at(mi, k, size)
        scene["integrator"] = {"type": "aov", "aovs": aovs, "integrator": {"type": "path", "max_depth": 8}}
        image = np.array(mi.render(mi.load_dict(scene), spp=spp, seed=100 + k), dtype=np.float32)
        color, albedo, normal, position = (np.ascontiguousarray(image[..., c:c + 3]) for c in (0, 3, 6, 9))
        depth = np.ascontiguousarray(image[..., 12:13])
        points, hit, emitter = centre_hits(mi, camera_at(mi, k, size), size)
        motion = motion_vectors(mi, camera_at(mi, k - 1, size), points, hit, size)
        albedo[emitter] = 0.0
        scene["integrator"] = {"type": "path", "max_depth": 8}
        reference = np.array(mi.render(mi.load_dict(scene), spp=reference_spp, seed=1000 + k), dtype=np.float32)
        inputs = dict(color=color, albedo=albedo, normal=normal, position=position, depth=depth, motion=motion)
        out.append({"inputs": inputs, "reference": np.ascontiguousarray(reference[..., :3])})
    return out


if __name__ == "__main__":
    import mitsuba as mi

    import filterjit

    mi.set_variant("llvm_ad_rgb")
    denoiser = filterjit.Denoiser()
    for k, frame in enumerate(render_sequence(mi, 6)):
        out = denoiser.denoise(**frame["inputs"])
        noisy = filterjit.relmse(frame["inputs"]["color"], frame["reference"])
        print(f"frame {k + 1}: relMSE {noisy:.3f} -> {filterjit.relmse(out, frame['reference']):.4f} "
              f"with {denoiser.filter} ({denoiser.frames} frames of history)")
