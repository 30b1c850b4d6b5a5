"""numpy's complex arithmetic as compiled kernels can reproduce it, bit for bit.

The reals' ``+ - * /``, ``sqrt`` and comparisons are correctly rounded IEEE operations, the
same in numpy and in any compiled loop; numpy's complex products and ``abs`` are not: their
SIMD loops depend on the CPU. On x86-64-v3 (AVX2 + FMA) numpy 2 computes ``np.multiply(a,
b)`` as ``(fma(ar, br, -(ai bi)), fma(ar, bi, ai br))`` (so the operands' order matters) and
``np.abs`` as ``L sqrt(fma(q, q, 1))`` (``L`` the larger part, ``q`` the smaller over it), on
older CPUs plainly (``ar br - ai bi``, libm's ``hypot``). :func:`cmul_re`, :func:`cmul_im`
and :func:`cabs` do either (:data:`FUSED`, :data:`PLAIN`), in plain Python and in kernels
(:func:`dynmap_sim.jit.fma`); :func:`numpy_complex_mode` probes numpy once per process and
says which one its loops match here (None: neither, e.g. a numpy whose AVX-512 loops use
another formula; the kernels' callers then keep numpy's code). Used by the compiled ray
caster (:mod:`dynmap_sim.sensors.raycast_numba`) and the people's geometry queries
(:mod:`dynmap_sim.world.people.obstacles_numba`).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from dynmap_sim.jit import compiled, fma, jitable, pick_kernel

#: Complex arithmetic as numpy's x86-64-v3 loops do it (fused multiply-adds).
FUSED = 1
#: Complex arithmetic as numpy's baseline loops do it (separate roundings, libm's hypot).
PLAIN = 0


@jitable
def cmul_re(ar: float, ai: float, br: float, bi: float, mode: int) -> float:
    """Real part of numpy's ``np.multiply(a, b)`` for complex ``a``, ``b`` in ``mode``."""
    if mode == FUSED:
        return fma(ar, br, -(ai * bi))
    return ar * br - ai * bi


@jitable
def cmul_im(ar: float, ai: float, br: float, bi: float, mode: int) -> float:
    """Imaginary part of numpy's ``np.multiply(a, b)`` (the operands' order matters)."""
    if mode == FUSED:
        return fma(ar, bi, ai * br)
    return ar * bi + ai * br


@jitable
def cabs(x: float, y: float, mode: int) -> float:
    """numpy's ``np.abs(x + iy)`` in ``mode`` (finite parts)."""
    if mode != FUSED:
        return math.hypot(x, y)
    ax, ay = abs(x), abs(y)
    big, small = max(ax, ay), min(ax, ay)
    if big == 0.0:
        return 0.0
    q = small / big
    return big * math.sqrt(fma(q, q, 1.0))


def _probe_py(ar, ai, br, bi, mode, out):  # type: ignore[no-untyped-def]
    """Product and ``abs`` of each pair in ``mode``, by the kernel's own helpers."""
    for i in range(ar.shape[0]):
        out[i, 0] = cmul_re(ar[i], ai[i], br[i], bi[i], mode)
        out[i, 1] = cmul_im(ar[i], ai[i], br[i], bi[i], mode)
        out[i, 2] = cabs(ar[i], ai[i], mode)


_probe = compiled(_probe_py)


@functools.cache
def numpy_complex_mode(python: bool = False) -> int | None:
    """:data:`FUSED` or :data:`PLAIN`, whichever reproduces numpy's complex products (of
    arrays, and of an array by a scalar) and ``abs`` on this install, or None.

    Probed once per process on 3,000 random pairs of three lengths (a fused and a plain
    product differ in the last bit on about a quarter of such pairs, so a wrong mode cannot
    pass); ``python``: probe the plain-Python helpers (numba not needed; slow)."""
    probe = pick_kernel(_probe_py, _probe, python, "kernels")
    rng = np.random.default_rng(20261128)
    for mode in (FUSED, PLAIN):
        ok = True
        for n in (1, 7, 2992):
            a = rng.normal(size=n) * 3.0 + 1j * rng.normal(size=n)
            b = rng.normal(size=n) + 1j * rng.normal(size=n) * 3.0
            for bb, ref in (
                (b, np.multiply(a, b)),
                (b[:1].repeat(n), np.multiply(a, complex(b[0]))),
            ):
                out = np.empty((n, 3))
                probe(a.real.copy(), a.imag.copy(), bb.real.copy(), bb.imag.copy(), mode, out)
                ok &= out[:, 0].tobytes() == ref.real.tobytes()
                ok &= out[:, 1].tobytes() == ref.imag.tobytes()
                ok &= out[:, 2].tobytes() == np.abs(a).tobytes()
        if ok:
            return mode
    return None
