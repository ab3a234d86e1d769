"""Intel Open Image Denoise on a frame of the given size, timed the way
docs/JOURNAL.md compares it with filterjit's forms: warm `denoise` calls
(colour + albedo + normal, HDR, CPU device, quality "high"), median of N.

    pip install pyoidn numpy
    python3 benches/oidn_timing.py 256 9

OIDN's run time does not depend on the image's content, so the frame is
random HDR data; its errors on real renders are in the mitsuba-256 samples'
BASELINES.md.
"""
import sys
import time
from importlib.metadata import version

import numpy as np
import pyoidn

side = int(sys.argv[1]) if len(sys.argv) > 1 else 256
repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 9
rng = np.random.default_rng(0)
color = (rng.random((side, side, 3), dtype=np.float32) ** 4 * 4).astype(np.float32)
albedo = rng.random((side, side, 3), dtype=np.float32)
normal = rng.random((side, side, 3), dtype=np.float32) * 2 - 1
start = time.perf_counter()
pyoidn.denoise(color, albedo, normal, hdr=True)
cold = time.perf_counter() - start
times = []
for _ in range(repeats):
    start = time.perf_counter()
    pyoidn.denoise(color, albedo, normal, hdr=True)
    times.append(time.perf_counter() - start)
times.sort()
print(f"oidn {side}x{side} color+albedo+normal: cold {cold * 1e3:.1f} ms, warm median {times[len(times) // 2] * 1e3:.1f} ms "
      f"[{times[0] * 1e3:.1f}, {times[-1] * 1e3:.1f}] over {repeats}; pyoidn {version('pyoidn')}")
