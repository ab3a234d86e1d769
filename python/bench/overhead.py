"""Per-call overhead of `filterjit.denoise` over the command line's filter time
(docs/JOURNAL.md, "From Python").

For each size, one input set (a public-render-like synthetic scene: noisy
colour, albedo, normals, positions, depth, variance) is denoised from numpy
with the default filter, warm (the kernel compiled and the device open), and
the same arrays written as a Mitsuba dataset are filtered by `filterjit
filter`, whose printed `filter` time is the device's work alone. The overhead
is the Python call's wall time minus that. Run with the installed wheel and
the binary of the same profile:

    python python/bench/overhead.py target/release/filterjit [SIZE ...]
"""

import re
import subprocess
import sys
import tempfile
import time
import pathlib

import numpy as np

import filterjit


def scene(size, seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    albedo = np.stack([0.2 + 0.6 * (x > 0.5), 0.3 + 0.4 * (y > 0.3), 0.5 + 0 * x], axis=2).astype(np.float32)
    light = 1.0 + 4.0 * np.exp(-((x - 0.3) ** 2 + (y - 0.6) ** 2) * 20)
    truth = albedo * light[..., None]
    noise = rng.exponential(1.0, (size, size, 3)).astype(np.float32)
    color = (truth * noise).astype(np.float32)
    normal = np.stack([x * 0, y * 0 + (x > 0.5), 1 - (x > 0.5) + 0 * y], axis=2).astype(np.float32)
    position = np.stack([x, y, 0 * x], axis=2).astype(np.float32)
    depth = (1 + x).astype(np.float32)
    variance = (truth * truth).astype(np.float32)
    return dict(color=color, albedo=albedo, normal=normal, position=position, depth=depth, variance=variance)


def write_dataset(folder, s):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    planes = [s["color"], s["albedo"], s["normal"], s["position"], s["depth"][..., None]]
    names = ["R", "G", "B", "albedo.R", "albedo.G", "albedo.B", "sh_normal.X", "sh_normal.Y", "sh_normal.Z",
             "position.X", "position.Y", "position.Z", "depth.T"]
    multi = np.ascontiguousarray(np.concatenate(planes, axis=2))
    mi.Bitmap(multi, mi.Bitmap.PixelFormat.MultiChannel, channel_names=names).write(str(folder / "noisy.exr"))
    mi.Bitmap(s["variance"], mi.Bitmap.PixelFormat.RGB).write(str(folder / "variance.exr"))


def main():
    binary = sys.argv[1]
    sizes = [int(a) for a in sys.argv[2:]] or [256, 1024]
    print(f"device: {filterjit.device_name()}")
    print(f"filter: {filterjit.choose(['albedo', 'normal', 'position', 'depth', 'variance'])[0]}")
    print("| size | denoise (median of 5, warm) | CLI `filter` (device, warm) | CLI load (EXR + preparation) | CLI pre-pass (first, compile included) | overhead over `filter` | overhead / denoise |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for size in sizes:
        s = scene(size)
        args = {k: v for k, v in s.items() if k != "color"}
        filterjit.denoise(s["color"], **args)  # compile and open the device
        times = []
        for _ in range(5):
            start = time.perf_counter()
            out = filterjit.denoise(s["color"], **args)
            times.append(time.perf_counter() - start)
        wall = float(np.median(times)) * 1e3
        with tempfile.TemporaryDirectory() as tmp:
            folder = pathlib.Path(tmp) / "scene"
            folder.mkdir()
            write_dataset(folder, s)
            run = subprocess.run([binary, "filter", str(folder), "-o", str(pathlib.Path(tmp) / "out.exr")],
                                 capture_output=True, text=True, check=True)
        filter_ms = float(re.search(r"\| filter ([0-9.]+) ms", run.stdout).group(1))
        load_ms = float(re.search(r"time\s+load ([0-9.]+) ms", run.stdout).group(1))
        prepass_ms = float(re.search(r"pre-pass ([0-9.]+) ms", run.stdout).group(1))
        overhead = wall - filter_ms
        print(f"| {size}² | {wall:.1f} ms | {filter_ms:.1f} ms | {load_ms:.1f} ms | {prepass_ms:.1f} ms | {overhead:.1f} ms | {overhead / wall:.0%} |")
        assert out.shape == s["color"].shape


if __name__ == "__main__":
    main()
