"""Makes the HDR-FLIP test cases: reference and test images (linear RGB)
and the reference implementation's error maps for them.

    pip install numpy flip-evaluator==1.7
    python3 tests/data/flip/make.py

Each case is CASE.f32: little-endian float32, reference (h*w*3), test
(h*w*3), FLIP map (h*w); its size is in cases.txt. Not run by the tests."""
import pathlib
import numpy as np
import flip_evaluator as flip

here = pathlib.Path(__file__).parent
rng = np.random.default_rng(7)


def case(name, ref, test):
    ref, test = ref.astype(np.float32), test.astype(np.float32)
    error, mean, params = flip.evaluate(ref, test, "HDR", applyMagma=False)
    h, w, _ = ref.shape
    data = np.concatenate([ref.ravel(), test.ravel(), error.astype(np.float32).ravel()])
    data.astype("<f4").tofile(here / f"{name}.f32")
    print(name, w, h, mean, params)
    return f"{name} {w} {h} {mean!r}\n"


lines = []
# A soft HDR gradient with Monte Carlo-like noise and a few fireflies.
h, w = 24, 32
y, x = np.mgrid[0:h, 0:w]
ref = np.stack([0.05 + 2.0 * x / w, 0.1 + 0.5 * y / h, 0.3 + 0.0 * x], -1)
test = ref * rng.gamma(4.0, 0.25, ref.shape)
test[5, 7] = [40.0, 35.0, 30.0]
test[17, 25] = [0.0, 90.0, 5.0]
lines.append(case("gradient", ref, test))
# An emitter far brighter than the rest, black pixels, edges; taller than wide.
h, w = 36, 20
ref = np.full((h, w, 3), 0.02)
ref[:, 10:] = [0.4, 0.2, 0.1]
ref[3:9, 4:9] = [200.0, 180.0, 150.0]
ref[30:, :6] = 0.0
test = np.clip(ref + rng.normal(0.0, 0.05, ref.shape), 0.0, None)
test[3:9, 4:9] *= 0.8
lines.append(case("emitter", ref, test))
(here / "cases.txt").write_text("".join(lines))
