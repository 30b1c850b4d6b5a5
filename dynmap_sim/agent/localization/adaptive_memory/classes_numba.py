"""Optional numba kernels of the point bookkeeping of one ``adaptive-memory`` scan (extra
``fast``): :meth:`.localizer.AdaptiveMemoryLocalizer.update`'s steps 2-4 around the
tracker, the long-term map and the semistatic test, one beam at a time instead of some thirty
numpy calls on arrays of a few hundred points:

* :func:`scan_points`: the valid returns, their range noise (§4.1, the URG-04LX's
  ``max(σ_min, σ_rel r)``), each one's tracker class (eq. 11: its box's, unknown outside a
  box) and box, and the static ones (the candidates of §4.3's ``u``);
* :func:`masked_beams`: the valid readings among the points MCL uses (§6.1), for
  :class:`.localizer.StaticPointFilter`;
* :func:`final_classes`: §4.4's semistatic test on the map's verdicts, the long-term map's
  veto of dynamic boxes it explains (``ltm_veto_dynamic``), the classes of every beam and
  their counts.

Integer and comparison work only, so the results are the numpy code's exactly
(:meth:`.localizer.AdaptiveMemoryLocalizer._scan_points` and ``_final_classes`` keep it);
the tests check the plain-Python kernels (what numba compiles) and the compiled ones against
it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
Int8Array = NDArray[np.int8]

#: :mod:`.object_tracker`'s point-class codes (repeated: the kernels take no module state).
_UNKNOWN, _DYNAMIC, _SEMISTATIC, _STATIC = 0, 1, 2, 3


def _scan_points_py(  # type: ignore[no-untyped-def]
    ranges, range_max_m, labels, box_cls, sigma_r_min_m, sigma_r_rel, vi, rv, sig_r, cls_v,
    lab_v, stat,
):  # fmt: skip
    """The valid returns (finite, ``0 < r < range_max_m``) in order: beam index ``vi``,
    range ``rv``, noise ``sig_r = max(sigma_r_min_m, sigma_r_rel r)`` (``np.maximum``'s
    choice), class ``cls_v`` (``box_cls`` of the beam's box ``labels``, unknown outside
    one) and box ``lab_v``; the positions among them of the static ones in ``stat``.
    Returns how many valid and how many static."""
    n = 0
    n_stat = 0
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if not (math.isfinite(r) and r > 0 and r < range_max_m):
            continue
        vi[n] = i
        rv[n] = r
        s = sigma_r_rel * r
        sig_r[n] = sigma_r_min_m if sigma_r_min_m >= s or sigma_r_min_m != sigma_r_min_m else s
        b = labels[i]
        lab_v[n] = b
        k = box_cls[b] if b >= 0 else _UNKNOWN
        cls_v[n] = k
        if k == _STATIC:
            stat[n_stat] = n
            n_stat += 1
        n += 1
    return n, n_stat


def _final_classes_py(  # type: ignore[no-untyped-def]
    cls_v, lab_v, explained, n_boxes, veto_share, vi, classes, counts, n_pts, n_expl
):
    """In place on ``cls_v`` (the valid returns' tracker classes): a dynamic point of a box
    at least ``veto_share`` of whose points (at least one) are ``explained`` becomes static,
    then every point but the dynamic ones that is not ``explained`` semistatic (§4.4);
    ``classes[vi] = cls_v`` (the others stay as they are: unknown) and ``counts`` the
    number of each class. ``n_pts``, ``n_expl``: ``n_boxes`` zeros (scratch)."""
    n = cls_v.shape[0]
    any_dyn = False
    for j in range(n):
        if cls_v[j] == _DYNAMIC and lab_v[j] >= 0:
            any_dyn = True
            break
    if any_dyn:
        for j in range(n):
            b = lab_v[j]
            if b >= 0:
                n_pts[b] += 1
                if explained[j]:
                    n_expl[b] += 1
        for j in range(n):
            b = lab_v[j]
            if cls_v[j] == _DYNAMIC and b >= 0:
                if n_expl[b] >= veto_share * max(n_pts[b], 1):
                    cls_v[j] = _STATIC
    for j in range(n):
        if cls_v[j] != _DYNAMIC and not explained[j]:
            cls_v[j] = _SEMISTATIC
        classes[vi[j]] = cls_v[j]
        counts[cls_v[j]] += 1


def _masked_beams_py(r, range_max_m, range_min_m, mask, use_mask, idx):  # type: ignore[no-untyped-def]
    """The beams MCL may use (``particle_filter``'s valid readings: finite,
    ``0 < r < range_max_m``, ``r >= range_min_m``) among those of ``mask`` (if
    ``use_mask``), in order, into ``idx``; returns how many."""
    n = 0
    for i in range(r.shape[0]):
        v = r[i]
        if math.isfinite(v) and v > 0 and v < range_max_m and v >= range_min_m:
            if not use_mask or mask[i]:
                idx[n] = i
                n += 1
    return n


_masked_beams = compiled(_masked_beams_py)
_scan_points = compiled(_scan_points_py)
_final_classes = compiled(_final_classes_py)


def scan_points(
    ranges: FloatArray,
    range_max_m: float,
    labels: IntArray,
    box_cls: Int8Array,
    sigma_r_min_m: float,
    sigma_r_rel: float,
    python: bool = False,
) -> tuple[IntArray, FloatArray, FloatArray, Int8Array, IntArray, IntArray]:
    """:func:`_scan_points_py` compiled (needs numba; ``python``: the plain kernel): ``vi,
    rv, sig_r, cls_v, lab_v, stat``."""
    kernel = pick_kernel(_scan_points_py, _scan_points, python, "adaptive-memory classes")
    n = len(ranges)
    vi, lab_v, stat = (np.empty(n, dtype=np.intp) for _ in range(3))
    rv, sig_r = np.empty(n), np.empty(n)
    cls_v = np.empty(n, dtype=np.int8)
    m, n_stat = kernel(ranges, float(range_max_m), labels, box_cls, float(sigma_r_min_m),
                       float(sigma_r_rel), vi, rv, sig_r, cls_v, lab_v, stat)  # fmt: skip
    return vi[:m], rv[:m], sig_r[:m], cls_v[:m], lab_v[:m], stat[:n_stat]


def final_classes(
    cls_v: Int8Array,
    lab_v: IntArray,
    explained: NDArray[np.bool_],
    n_boxes: int,
    veto_share: float,
    vi: IntArray,
    n_beams: int,
    python: bool = False,
) -> tuple[Int8Array, NDArray[np.int64]]:
    """:func:`_final_classes_py` compiled (needs numba; ``python``: the plain kernel), in
    place on ``cls_v``: the classes of the ``n_beams`` beams and the count of each class."""
    kernel = pick_kernel(_final_classes_py, _final_classes, python, "adaptive-memory classes")
    classes = np.zeros(n_beams, dtype=np.int8)  # _UNKNOWN
    counts = np.zeros(4, dtype=np.int64)
    kernel(cls_v, lab_v, explained, int(n_boxes), float(veto_share), vi, classes, counts,
           np.zeros(n_boxes, dtype=np.int64), np.zeros(n_boxes, dtype=np.int64))  # fmt: skip
    return classes, counts


def masked_beams(
    r: FloatArray,
    range_max_m: float,
    range_min_m: float,
    mask: NDArray[np.bool_] | None,
    python: bool = False,
) -> IntArray:
    """:func:`_masked_beams_py` compiled (needs numba; ``python``: the plain kernel): the
    indices of the valid readings of ``r`` (float64) in ``mask`` (None: all)."""
    kernel = pick_kernel(_masked_beams_py, _masked_beams, python, "adaptive-memory classes")
    idx = np.empty(len(r), dtype=np.intp)
    m = np.zeros(1, dtype=np.bool_) if mask is None else mask
    n = kernel(r, float(range_max_m), float(range_min_m), m, mask is not None, idx)
    return idx[:n]
