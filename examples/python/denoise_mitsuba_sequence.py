"""Denoise a Mitsuba 3 sequence in the same process, frame by frame, with the
history carried from frame to frame (README, "From Python").

A Cornell box seen by a camera that slides sideways: each frame is rendered at
1 spp with its albedo, normal, position and depth; the motion vectors are
what Blender's Vector pass holds (where each pixel's surface was in the frame
before, minus where it is, in pixels, y up), computed from the position AOV
and the frame before's camera. Needs `pip install mitsuba` and Mitsuba's LLVM
variant (Debian: libllvm19).
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


def motion_vectors(mi, scene_before, position, size):
    """Blender's Vector pass X, Y for each pixel: its surface (`position`)
    on the frame before's film minus the pixel's centre, y up."""
    sensor = mi.load_dict(scene_before).sensors()[0]
    points = position.reshape(-1, 3)
    it = mi.Interaction3f()
    it.p = mi.Point3f(points[:, 0], points[:, 1], points[:, 2])
    ds, _ = sensor.sample_direction(it, mi.Point2f(0.5, 0.5))
    before = np.stack([np.array(ds.uv.x), np.array(ds.uv.y)], -1).reshape(size, size, 2)
    ys, xs = np.mgrid[0:size, 0:size].astype(np.float32) + 0.5
    return np.ascontiguousarray(np.stack([before[..., 0] - xs, ys - before[..., 1]], -1), dtype=np.float32)


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
        motion = motion_vectors(mi, camera_at(mi, k - 1, size), position, size)
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
