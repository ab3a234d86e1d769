"""filterjit from Python: denoise renders held as numpy arrays, and check,
simplify, compile and export filter-weight expressions.

The binding is thin: every function runs the same Rust code as the
``filterjit`` command line, so ``denoise`` gives the pixels ``filterjit
filter`` gives on the same inputs and device. One GPU device is opened on
first use and kept for the process; the adapter is chosen as the command line
chooses it (``FILTERJIT_BACKEND``, ``FILTERJIT_ADAPTER``).

    import filterjit
    out = filterjit.denoise(color, albedo=albedo, normal=normal, position=position)
    print(filterjit.relmse(out, reference), filterjit.flip(out, reference))

    # A sequence: the temporal state carried from frame to frame.
    denoiser = filterjit.Denoiser()
    for frame in frames:
        out = denoiser.denoise(frame.color, albedo=frame.albedo, normal=frame.normal,
                               position=frame.position, depth=frame.depth, motion=frame.motion)
"""

import os as _os

# Mesa's Vulkan device-select layer probes for a display and prints errors
# without one; filterjit chooses its adapter itself (as `filterjit` does).
_os.environ.setdefault("NODEVICE_SELECT", "1")

from . import _filterjit  # noqa: E402

# The functions are the binding's own; their docstrings are its Rust doc
# comments (python/src/lib.rs), and __init__.pyi gives their types.
from ._filterjit import (  # noqa: E402
    Denoiser,
    check,
    choose,
    compile,
    denoise,
    device_name,
    export,
    flip,
    light,
    relmse,
    simplify,
)

__all__ = [
    "denoise",
    "Denoiser",
    "choose",
    "check",
    "simplify",
    "compile",
    "export",
    "relmse",
    "flip",
    "light",
    "device_name",
    "SHIPPED_BY_QUALITY",
]

SHIPPED_BY_QUALITY = tuple(_filterjit.SHIPPED_BY_QUALITY)
