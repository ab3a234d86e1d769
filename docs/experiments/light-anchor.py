"""A gated coarse light anchor, tried offline on filterjit's outputs (docs/JOURNAL.md,
"The moving light's error is lag at low frequency"). Not part of filterjit.

For each output o of the filter and the frame's noisy input n (luminances lo, li),
with G a Gaussian of sigma pixels:
    z    = |G li - G lo| / sqrt((G li^2 - (G li)^2) / (4 pi sigma^2))   (a standard error)
    t    = clamp((z - k) / k, 0, 1)
    o'   = o * (1 + t (G li / G lo - 1))
the output's light pulled to the frame's own where the two differ by more than k
standard errors of the frame's local mean: a history that lags a moving light, or
passes that lose light where it is sparse.

    python light-anchor.py seq SEQ_DIR OUT_DIR FIRST    # filterjit's own sequences
    python light-anchor.py cycles SEQ_DIR OUT_DIR FIRST # Cycles noisy/ reference/
    python light-anchor.py single DIR OUT.exr [DIR OUT.exr ...]

Needs numpy, scipy and OpenEXR (pip). relMSE is filterjit's (summed over RGB).
"""
import os
import sys

import numpy as np
import OpenEXR
from scipy.ndimage import gaussian_filter

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
SETTINGS = ((None, None), (4, 2), (4, 3), (8, 2))


def read(path):
    channels = OpenEXR.File(path).channels()
    for name in ("RGB", "ViewLayer.Combined"):
        if name in channels:
            return np.asarray(channels[name].pixels, dtype=np.float64)[..., :3]
    raise SystemExit(f"{path}: neither RGB nor ViewLayer.Combined")


def lum(x):
    return np.maximum(x, 0) @ LUMINANCE


def relmse(o, r):
    return 3 * np.mean((o - r) ** 2 / (r**2 + 0.01))


def anchored(noisy, out, sigma, k):
    li, lo = lum(noisy), lum(out)
    gi, go = gaussian_filter(li, sigma, mode="reflect"), gaussian_filter(lo, sigma, mode="reflect")
    spread = np.maximum(gaussian_filter(li * li, sigma, mode="reflect") - gi * gi, 0)
    error = np.sqrt(spread / (4 * np.pi * sigma * sigma)) + 1e-4
    t = np.clip((np.abs(gi - go) / error - k) / k, 0, 1)
    return out * (1 + t * (gi / np.maximum(go, 1e-6) - 1))[..., None]


def report(triples, sequence):
    for sigma, k in SETTINGS:
        outs = [o if sigma is None else anchored(n, o, sigma, k) for n, o, _ in triples]
        refs = [r for _, _, r in triples]
        errors = [relmse(o, r) for o, r in zip(outs, refs)]
        light = [lum(o).mean() / lum(r).mean() for o, r in zip(outs, refs)]
        line = f"sigma {sigma} k {k}: relMSE " + (f"{np.mean(errors):.5f}" if sequence else " ".join(f"{e:.5f}" for e in errors))
        if sequence:
            flicker = np.mean([np.mean(np.abs((outs[t] - outs[t - 1]) - (refs[t] - refs[t - 1]))) for t in range(1, len(outs))])
            line += f" flicker {flicker:.5f}"
        print(line + f" light {min(light):.3f}-{max(light):.3f}")


def main(kind, *args):
    if kind == "single":
        report([(read(f"{d}/noisy.exr"), read(o), read(f"{d}/reference.exr")) for d, o in zip(args[::2], args[1::2])], False)
        return
    seq, out, first = args[0], args[1], int(args[2])
    if kind == "seq":
        frames = sorted(f for f in os.listdir(seq) if f.startswith("frame_"))
        paths = [(f"{seq}/{f}/noisy.exr", f"{out}/{f}.exr", f"{seq}/{f}/reference.exr") for f in frames]
    else:
        frames = sorted(os.listdir(f"{seq}/noisy"))
        paths = [(f"{seq}/noisy/{f}", f"{out}/{f}", f"{seq}/reference/{f}") for f in frames]
    report([tuple(read(p) for p in triple) for triple in paths[first - 1 :]], True)


if __name__ == "__main__":
    main(*sys.argv[1:])
