"""Turn `filterjit render` datasets into what the benchmark page reads.

    python frames.py OUT_DIR LABEL=DATASET_DIR[:PAD_TO_HEIGHT] ...

For each dataset: raw little-endian f32 RGBA files (top row first, as
web/filterjit.js's filterArrays takes them) of the noisy colour, the albedo,
the shading normal, the world position, the colour variance and the
reference; and OUT_DIR/frames.json with their sizes and the scales filterjit's
own loader would normalise the features by (src/scene/preprocess.rs: 1 / the
99.9th percentile of the lengths, nearest rank), so the export sees what
`filterjit filter` feeds its kernels.

PAD_TO_HEIGHT: `filterjit render` cannot write a 1280x720 frame on this
machine (one storage buffer would be 140 MB, over the 128 MiB binding limit
lavapipe has), so the 720p frame is a 1280x688 render mirrored by 16 rows at
the top and bottom. Both denoisers then process a true 1280x720 frame; the
page computes the errors on the rendered rows only (`valid_rows`).
"""

import json
import math
import os
import sys

import numpy as np
import OpenEXR

# src/scene/preprocess.rs's NORMALISATION_PERCENTILE.
PERCENTILE = 0.999
# src/semantics.rs's COLOR_LIMIT: the loader clamps colour to it.
COLOR_LIMIT = 1e6


def channels(path, names):
    with OpenEXR.File(path, separate_channels=True) as exr:
        found = exr.channels()
        missing = [n for n in names if n not in found]
        if missing:
            raise SystemExit(f"{path}: no channel {', '.join(missing)} (has {', '.join(sorted(found))})")
        return np.stack([np.asarray(found[n].pixels, dtype=np.float32) for n in names], axis=-1)


def sanitized(values, limit):
    # As the loader does: non-finite values read as 0, magnitudes clamped.
    return np.clip(np.nan_to_num(values, nan=0.0, posinf=0.0, neginf=0.0), -limit, limit)


def robust_scale(magnitudes):
    """preprocess::robust_scale: the nearest-rank 99.9th percentile, 1 where it is 0."""
    values = np.sort(magnitudes.ravel().astype(np.float32))
    rank = min(max(math.ceil(values.size * PERCENTILE), 1), values.size)
    scale = float(values[rank - 1])
    return scale if scale > 0 and math.isfinite(scale) else 1.0


def rgba(values):
    """H x W x (1 or 3) -> H x W x 4 f32, alpha 1 (a scalar in .x, as the export reads it)."""
    h, w, c = values.shape
    out = np.zeros((h, w, 4), dtype="<f4")
    out[..., :c] = values
    out[..., 3] = 1.0
    return out


def main():
    out_dir, specs = sys.argv[1], sys.argv[2:]
    os.makedirs(out_dir, exist_ok=True)
    frames = []
    for spec in specs:
        label, rest = spec.split("=", 1)
        dataset, _, pad_to = rest.partition(":")
        meta = json.load(open(os.path.join(dataset, "meta.json")))
        noisy = os.path.join(dataset, "noisy.exr")
        images = {
            "color": sanitized(channels(noisy, ["R", "G", "B"]), COLOR_LIMIT),
            "albedo": sanitized(channels(noisy, ["Albedo.R", "Albedo.G", "Albedo.B"]), np.inf),
            "normal": sanitized(channels(noisy, ["Ns.X", "Ns.Y", "Ns.Z"]), np.inf),
            "position": sanitized(channels(noisy, ["P.X", "P.Y", "P.Z"]), np.inf),
            # The loader's colorVariance: the mean of the three channels' variances.
            "variance": sanitized(channels(noisy, ["Variance.R", "Variance.G", "Variance.B"]), np.inf).mean(
                axis=-1, keepdims=True
            ),
            "reference": sanitized(
                channels(os.path.join(dataset, "reference.exr"), ["R", "G", "B"]), COLOR_LIMIT
            ),
        }
        height, width = images["color"].shape[:2]
        # The scales of the rendered frame (before any padding, which only repeats its rows).
        length = lambda v: np.sqrt((v.astype(np.float64) ** 2).sum(axis=-1))
        scales = {
            "normal": 1 / robust_scale(length(images["normal"])),
            "texture": 1 / robust_scale(length(images["albedo"])),
            "worldPosition": 1 / robust_scale(length(images["position"])),
            "colorVariance": 1 / robust_scale(np.abs(images["variance"])),
        }
        valid = [0, height]
        if pad_to:
            extra = int(pad_to) - height
            top = extra // 2
            if extra < 0 or extra > 2 * (height - 1):
                raise SystemExit(f"{dataset}: cannot mirror {height} rows to {pad_to}")
            images = {k: np.pad(v, ((top, extra - top), (0, 0), (0, 0)), mode="reflect") for k, v in images.items()}
            valid = [top, top + height]
            height = int(pad_to)
        folder = os.path.join(out_dir, label)
        os.makedirs(folder, exist_ok=True)
        for name, values in images.items():
            rgba(values).tofile(os.path.join(folder, f"{name}.f32"))
        frames.append(
            {
                "label": label,
                "width": width,
                "height": height,
                "valid_rows": valid,
                "rendered": f"{width}x{valid[1] - valid[0]}",
                "scene": meta["scene"],
                "spp": meta["spp"],
                "reference_spp": meta["reference_spp"],
                "reference_residual_relmse": meta.get("reference_residual_relmse"),
                "seed": meta["seed"],
                "files": {name: f"{label}/{name}.f32" for name in images},
                "scales": scales,
            }
        )
        print(f"{label}: {meta['scene']} {width}x{height} (rows {valid[0]}..{valid[1]} rendered), "
              f"{meta['spp']} spp, reference {meta['reference_spp']} spp")
    json.dump({"frames": frames}, open(os.path.join(out_dir, "frames.json"), "w"), indent=1)


if __name__ == "__main__":
    main()
