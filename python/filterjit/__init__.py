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
"""

import os as _os

# Mesa's Vulkan device-select layer probes for a display and prints errors
# without one; filterjit chooses its adapter itself (as `filterjit` does).
_os.environ.setdefault("NODEVICE_SELECT", "1")

from . import _filterjit  # noqa: E402

__all__ = [
    "denoise",
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


def denoise(
    color,
    *,
    albedo=None,
    normal=None,
    position=None,
    depth=None,
    variance=None,
    spp=None,
    filter=None,
    pipeline=None,
    radius=None,
):
    """Denoise a render on the GPU and return the filtered colour.

    :param color: noisy linear RGB, float32, shape (H, W, 3).
    :param albedo: the surfaces' albedo (Mitsuba's ``albedo`` AOV), (H, W, 3).
    :param normal: shading normals (Mitsuba's ``sh_normal``), (H, W, 3).
    :param position: world positions (Mitsuba's ``position``), (H, W, 3).
    :param depth: depth (Mitsuba's ``depth``), (H, W) or (H, W, 1).
    :param variance: per-pixel sample variance of the colour, (H, W), (H, W, 1)
        or (H, W, 3) (the mean over channels is used, as from files).
    :param spp: samples per pixel of ``color`` (for information only).
    :param filter: a shipped filter's name (``"@evolvedAtrous3x3"``), an
        expression, or ``"@FILE:NAME"`` (a hall of fame entry). By default the
        best shipped filter whose inputs are given, by the rule the command
        line uses (see :func:`choose`).
    :param pipeline: the filter pipeline, e.g. ``"outliers=2,demodulate,atrous=5"``;
        by default the one the filter was stored with.
    :param radius: window radius of the ``window`` form; by default the stored one, else 5.
    :returns: float32 array of shape (H, W, 3).
    :raises TypeError: an input is not a float32 numpy array.
    :raises ValueError: a shape differs from ``color``'s, a value is not
        finite, an expression is invalid (with its line and column), a filter
        is unknown, or the filter needs an input that was not given.
    :raises RuntimeError: no GPU adapter, or the device failed.

    The GIL is released while the GPU works.
    """
    return _filterjit.denoise(
        color,
        albedo=albedo,
        normal=normal,
        position=position,
        depth=depth,
        variance=variance,
        spp=spp,
        filter=filter,
        pipeline=pipeline,
        radius=radius,
    )


def choose(inputs):
    """The shipped filter :func:`denoise` takes when given ``inputs`` (names
    among ``albedo``, ``normal``, ``position``, ``depth``, ``variance``; the
    colour is always there): ``(name, pipeline, why)``."""
    return _filterjit.choose(list(inputs))


def check(expr):
    """Parse and type-check an expression (text, ``@name`` or ``@FILE[:NAME]``):
    ``{"canonical": str, "length": int, "inputs": [str]}``.

    :raises ValueError: the expression is invalid; the message gives the line
        and column with a caret.
    """
    return _filterjit.check(expr)


def simplify(expr):
    """The cheapest equivalent expression (equality saturation with rules
    exact under filterjit's numeric semantics), as text."""
    return _filterjit.simplify(expr)


def compile(expr, pipeline=None):
    """The validated WGSL compute kernel of an expression (the one ``filterjit
    compile`` prints), shaped for ``pipeline`` (default: the stored one, else ``window``)."""
    return _filterjit.compile(expr, pipeline)


def export(expr, target="wgsl", pipeline=None, format="rgba16float"):
    """A standalone shader for an engine, as ``filterjit export`` writes it:
    ``(shader, manifest)``.

    ``shader`` is text (``bytes`` of SPIR-V words for ``target="spirv"``);
    ``manifest`` is the manifest as a dict (bindings, uniform, passes, order of
    dispatches). Where the pipeline has a pre-pass, its shader is
    ``manifest["prepass"]["source"]``.

    :param target: ``wgsl``, ``glsl``, ``hlsl``, ``msl`` or ``spirv``.
    :param format: texel format of the output storage texture.
    """
    return _filterjit.export(expr, target, pipeline, format)


def relmse(image, reference):
    """relMSE of ``image`` against ``reference`` (float32 (H, W, 3)): the mean
    over pixels of sum_rgb (c - g)^2 / (g^2 + 0.01), as the command line reports it."""
    return _filterjit.relmse(image, reference)


def flip(image, reference):
    """Mean HDR-FLIP of ``image`` against ``reference`` (float32 (H, W, 3)),
    as the command line reports it (a port of NVlabs' FLIP 1.7)."""
    return _filterjit.flip(image, reference)


def light(image, reference):
    """``image``'s mean luminance over ``reference``'s (float32 (H, W, 3)):
    1 keeps the light, below 1 is darker. A denoiser's bias; ``None`` for a
    black reference."""
    return _filterjit.light(image, reference)


def device_name():
    """The GPU adapter :func:`denoise` runs on (opening it if needed)."""
    return _filterjit.device_name()
