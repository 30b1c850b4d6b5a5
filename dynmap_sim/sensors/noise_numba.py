"""Optional numba kernels of the lidar's noise model (:meth:`Lidar._noise
<dynmap_sim.sensors.lidar.Lidar._noise>`, extra ``fast``) for one scan and one generator.

The numpy model is a few dozen numpy calls on one scan's beams, so its cost is call
overhead. Here the arithmetic between the random draws is done in four compiled loops;
the draws stay numpy's (``rng.standard_normal``, ``rng.random``), made in the same order
and the same sizes as the numpy model makes them. Every operation is the numpy code's, on
the same operands and in the same order, with IEEE double arithmetic that has one correctly
rounded result (``*``, ``+``, ``-``, comparisons, ``abs``, the float32 rounding): the
readings are those of the numpy model bit for bit (the tests compare them). Where a beam is
written twice (a beam between two edges of a mixed pixel), the later write wins, as in
numpy's fancy assignment.

Each kernel is plain Python (what the tests also run), compiled with
:func:`dynmap_sim.jit.compiled` when numba is installed.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.jit import numba_available as numba_available  # re-exported

if TYPE_CHECKING:
    from dynmap_sim.sensors.lidar import LidarNoise

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def _ranges_py(  # type: ignore[no-untyped-def]
    r, out, bias, sigma_rel, sigma_m, biased, r_max, mixed, jump, left
):
    """Range noise in place: ``out`` (standard normal draws) := ``out * sigma + r`` (``+
    bias`` when ``biased``), ``sigma = max(sigma_rel * r, sigma_m)`` (``r`` counting 0 for
    no hit; ``sigma_rel == 0``: ``sigma_m``); with ``mixed``, the left beams of the depth
    edges (``|r[i + 1] - r[i]| > jump``, both hit) into ``left``. Returns their number."""
    n = r.shape[0]
    for i in range(n):
        ri = r[i]
        if sigma_rel != 0.0:
            s = sigma_rel * (ri if ri <= r_max else 0.0)
            if not s >= sigma_m:  # np.maximum(s, sigma_m)
                s = sigma_m
        else:
            s = sigma_m
        v = out[i] * s
        out[i] = v + (ri + bias[i] if biased else ri)
    n_edges = 0
    if mixed:
        for i in range(n - 1):
            a = r[i]
            b = r[i + 1]
            if a <= r_max and b <= r_max and abs(b - a) > jump:
                left[n_edges] = i
                n_edges += 1
    return n_edges


def _pick_py(left, n_edges, pick, p_mixed, beams, others):  # type: ignore[no-untyped-def]
    """The beams (all left beams of the edges, then all right beams) whose ``pick`` draw is
    below ``p_mixed``, and the beam across the edge from each. Returns their number."""
    m = 0
    for j in range(2 * n_edges):
        if pick[j] < p_mixed:
            b = left[j] if j < n_edges else left[j - n_edges] + 1
            beams[m] = b
            others[m] = b + 1 if j < n_edges else b - 1
            m += 1
    return m


def _mix_and_rare_py(  # type: ignore[no-untyped-def]
    r, out, beams, others, w, m, u, p3, r_max, rare
):
    """Mixed pixels: ``out[b] := r[b] + w (r[o] - r[b])`` for the ``m`` picked beams in
    order; then the beams that hit with ``u < p3`` (rare events) into ``rare`` (when
    ``p3 > 0``). Returns their number."""
    for j in range(m):
        b = beams[j]
        rb = r[b]
        out[b] = rb + w[j] * (r[others[j]] - rb)
    n_rare = 0
    if p3 > 0.0:
        for i in range(r.shape[0]):
            if u[i] < p3 and r[i] <= r_max:
                rare[n_rare] = i
                n_rare += 1
    return n_rare


def _finish_py(  # type: ignore[no-untyped-def]
    r, out, u, rare, n_rare, short, p1, p2, r_min, r_max, res
):
    """Rare events (``u < p1``: dropout ``+inf``; ``< p2``: a short return
    ``r_min + short (r - r_min)``; else NaN), then REP-117 (``-inf`` below ``r_min``,
    ``+inf`` beyond ``r_max``) and the float32 readings ``res``."""
    for j in range(n_rare):
        i = rare[j]
        ur = u[i]
        if ur < p1:
            out[i] = math.inf
        elif ur < p2:
            out[i] = r_min + short[j] * (r[i] - r_min)
        else:
            out[i] = math.nan
    for i in range(out.shape[0]):
        v = out[i]
        if v < r_min:
            v = -math.inf
        elif v > r_max:
            v = math.inf
        res[i] = v


_ranges = compiled(_ranges_py)
_pick = compiled(_pick_py)
_mix_and_rare = compiled(_mix_and_rare_py)
_finish = compiled(_finish_py)

_EMPTY = np.zeros(0)


def noise_scan(
    r: FloatArray,
    rng: np.random.Generator,
    bias: FloatArray,
    noise: LidarNoise,
    range_min_m: float,
    range_max_m: float,
    python: bool = False,
) -> NDArray[np.float32]:
    """The noisy readings of one scan's true ranges ``r`` ``(n,)`` (float64, C-contiguous)
    drawn from ``rng``: what :meth:`Lidar.apply_noise` gives, with the same draws.

    ``bias`` is the lidar's per-beam systematic error, ``noise`` its
    :class:`~dynmap_sim.sensors.lidar.LidarNoise`; ``python`` runs the uncompiled kernels.
    """
    nz = noise
    n = r.shape[0]
    ranges, pick_, mix, finish = (
        (_ranges_py, _pick_py, _mix_and_rare_py, _finish_py)
        if python
        else (_ranges, _pick, _mix_and_rare, _finish)
    )
    r_max = float(range_max_m)
    out = rng.standard_normal(n)
    mixed = nz.p_mixed > 0.0
    left = np.empty(max(n - 1, 0), dtype=np.int64)
    n_edges = ranges(
        r,
        out,
        bias,
        float(nz.sigma_rel),
        float(nz.sigma_m),
        nz.systematic_m != 0.0,
        r_max,
        mixed,
        float(nz.mixed_jump_m),
        left,
    )
    p1 = nz.p_dropout
    p2 = p1 + nz.p_short
    p3 = p2 + nz.p_invalid
    beams = others = left
    w = _EMPTY
    m = 0
    if n_edges:
        pick = rng.random(2 * n_edges)
        beams = np.empty(2 * n_edges, dtype=np.int64)
        others = np.empty(2 * n_edges, dtype=np.int64)
        m = pick_(left, n_edges, pick, float(nz.p_mixed), beams, others)
        w = rng.random(m)
    u = rng.random(n) if p3 > 0.0 else _EMPTY
    rare = np.empty(n, dtype=np.int64)
    n_rare = mix(r, out, beams, others, w, m, u, float(p3), r_max, rare)
    short = rng.random(n_rare) if n_rare else _EMPTY
    res = np.empty(n, dtype=np.float32)
    finish(r, out, u, rare, n_rare, short, float(p1), float(p2), float(range_min_m), r_max, res)
    return res
