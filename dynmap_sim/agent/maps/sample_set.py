"""Dynamic sample sets of many rays at once (Biber & Duckett 2009, §3.1–3.3, §4.2).

One :class:`SampleSets` object holds ``n_rays`` independent sample sets of capacity
``n_samples`` each, as a ``uint16`` array of range samples in millimetres (2 bytes per sample,
§5.1) plus a per-ray fill count. Valid samples of ray ``r`` are ``samples_mm[r, :count[r]]``.

* :meth:`SampleSets.update` — the update rule of §3.1 with update ratio ``u``: remove ``u·n``
  randomly chosen samples and add ``u·n`` randomly chosen measurements (while the set is not
  full, the new samples go to free slots instead: the filling phase). ``u·n`` that is not an
  integer is rounded stochastically so that every old sample survives a step with probability
  exactly ``1 − u`` — which gives the age distribution ``p(t) = u(1 − u)^t`` of eq. 3 (§3.2).
  A ray that received fewer measurements than ``u·n`` in a step takes all of them (a
  measurement is never duplicated).
* :meth:`SampleSets.estimates` — the robust estimates of §3.3: median (eq. 4; for an even
  number of samples the *lower* of the two middle samples, never their mean, so the estimate
  is always a measured value — requirement 4), ``σ = 1.48·MAD`` (eq. 5) and the outlier ratio
  (share of samples farther than 3σ from the median).
* :meth:`SampleSets.log_likelihood` — the perceptual model eq. 6–8: a mixture of
  ``N(ρ, σ²)`` and ``U(0, maxRange)`` weighted by the outlier ratio.

The per-ray bookkeeping of an update and the robust estimates run in compiled kernels (at
the end of this module); the random draws are made in numpy and handed to them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.jit import compiled, jitable

#: Largest storable range [mm] (uint16); also the sort key of empty slots.
MAX_RANGE_MM = 65535

#: 1/sqrt(2π)
_INV_SQRT_2PI = 0.3989422804014327


@dataclass(frozen=True)
class RayEstimates:
    """Robust per-ray statistics of a sample set (§3.3), each of shape ``(n_rays,)``.

    ``rho_m`` is the median (a measured value; NaN where a ray has no sample), ``sigma_m`` is
    1.48·MAD, ``outlier_ratio`` the share of samples outside ``ρ ± 3σ``, ``count`` the number
    of samples.
    """

    rho_m: NDArray[np.float64]
    sigma_m: NDArray[np.float64]
    outlier_ratio: NDArray[np.float64]
    count: NDArray[np.int64]


def to_mm(range_m: ArrayLike) -> NDArray[np.uint16]:
    """Ranges in metres -> rounded uint16 millimetres (clipped to ``[0, 65.535]`` m)."""
    r = np.asarray(range_m, dtype=np.float64)
    return np.clip(np.rint(r * 1000.0), 0, MAX_RANGE_MM).astype(np.uint16)


class SampleSets:
    """``n_rays`` dynamic sample sets of ``n_samples`` each, update ratio ``update_ratio``."""

    def __init__(
        self, n_rays: int, n_samples: int, update_ratio: float, first_step_fills: bool = True
    ) -> None:
        if n_rays < 1 or n_samples < 1:
            raise ValueError("n_rays and n_samples must be >= 1")
        if not 0.0 <= update_ratio <= 1.0:
            raise ValueError(f"update_ratio must be in [0, 1], got {update_ratio}")
        self.n_rays = int(n_rays)
        self.n_samples = int(n_samples)
        self.update_ratio = float(update_ratio)
        #: True: a ray's first time step takes up to ``n`` measurements (the toy of §3.5,
        #: "initialized using the measurements of the first time-step"); False: the plain
        #: §3.1 rule from the start ("until it is full an update just consists of adding
        #: u·n randomly chosen samples").
        self.first_step_fills = bool(first_step_fills)
        self.samples_mm = np.zeros((self.n_rays, self.n_samples), dtype=np.uint16)
        self.count = np.zeros(self.n_rays, dtype=np.uint16)
        #: Rays that had their first time step (§3.5: a set is initialized with the
        #: measurements of its first time step; afterwards the §3.1 rule applies).
        self.initialized = np.zeros(self.n_rays, dtype=bool)
        self._est: RayEstimates | None = None
        self._table: tuple[tuple[float, float, float], NDArray[np.float64]] | None = None
        self._version = 0

    @property
    def version(self) -> int:
        """Number of :meth:`update` steps so far (0 for sets pickled before it was counted):
        a cache of anything derived from the samples is valid while it does not change."""
        return self._version

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.__dict__.setdefault("_version", 0)  # (pickles from before it was counted)

    def _changed(self) -> None:
        """Drop the caches of the samples' statistics and count the change."""
        self._est = None
        self._table = None
        self._version = self.version + 1

    @property
    def fills_first_step(self) -> bool:
        """:attr:`first_step_fills` (True for sets pickled before the option existed)."""
        return bool(self.__dict__.get("first_step_fills", True))

    # ------------------------------------------------------------------ memory
    @property
    def nbytes(self) -> int:
        """Bytes of the sample storage (2 per sample slot) plus the per-ray counts."""
        return int(self.samples_mm.nbytes + self.count.nbytes + self.initialized.nbytes)

    @property
    def sample_bytes(self) -> int:
        """Bytes of the sample storage alone: ``2 · n_rays · n_samples``."""
        return int(self.samples_mm.nbytes)

    def copy(self) -> SampleSets:
        """A deep copy (used for the frozen snapshot of the static-map variants, §5.3)."""
        out = SampleSets(self.n_rays, self.n_samples, self.update_ratio, self.fills_first_step)
        out.samples_mm[:] = self.samples_mm
        out.count[:] = self.count
        out.initialized[:] = self.initialized
        out._est = self._est
        return out

    # ------------------------------------------------------------------ update rule
    def _n_new(self, n_groups: int, rng: np.random.Generator) -> NDArray[np.int64]:
        """``u·n`` per ray, rounded stochastically when it is not an integer."""
        k = self.update_ratio * self.n_samples
        base = int(np.floor(k))
        frac = k - base
        out = np.full(n_groups, base, dtype=np.int64)
        if frac > 1e-12:
            out += rng.random(n_groups) < frac
        return out

    def update(
        self,
        ray_idx: ArrayLike,
        values_mm: ArrayLike,
        rng: np.random.Generator,
        *,
        fill: bool = False,
        initialize: bool = True,
    ) -> None:
        """Apply one time step of the §3.1 rule with the measurements ``(ray_idx, values_mm)``.

        The measurements are a flat list: measurement ``i`` belongs to ray ``ray_idx[i]``
        (any order, any multiplicity). Rays without measurements are unchanged.

        With :attr:`first_step_fills`, a ray's first time step *initializes* it (§3.5:
        "initialized using the measurements of the first time-step"): it takes up to ``n``
        measurements; from then on (and always without it) the §3.1 rule, with its filling
        phase of ``u·n`` per step while not full, applies. ``fill=True``
        fills free slots without removing anything; with ``initialize=False`` it does not
        count as the first time step (used to seed a new local map with one scan, §4.4).

        The random draws are made here (a random order of each ray's measurements, the
        ``u·n`` rounding, the keys of the slots to replace), the bookkeeping in the compiled
        kernels below (:func:`_sort_by_ray`, :func:`_plan_update`, :func:`_write_update`).
        """
        ray = np.asarray(ray_idx, dtype=np.int64).ravel()
        val = np.asarray(values_mm).ravel()
        if ray.shape != val.shape:
            raise ValueError("ray_idx and values_mm must have the same length")
        if ray.size == 0:
            return
        if val.dtype != np.uint16:
            val = np.clip(val, 0, MAX_RANGE_MM).astype(np.uint16)
        m = ray.size
        keys = ray + rng.random(m)  # by ray, random within a ray: "randomly chosen from M"
        r_s = np.empty(m, dtype=np.int64)
        v_s = np.empty(m, dtype=np.uint16)
        first = np.empty(m, dtype=np.int64)
        n_runs = _sort_by_ray(ray, keys, val, self.n_rays, r_s, v_s, first)
        if n_runs < 0:
            raise ValueError("ray index out of range")
        first = first[:n_runs]
        n_rule = np.zeros(n_runs, dtype=np.int64) if fill else self._n_new(n_runs, rng)
        n_new = np.empty(n_runs, dtype=np.int64)
        n_add = np.empty(n_runs, dtype=np.int64)
        n_rep = _plan_update(
            r_s, first, self.count, self.initialized, self.n_samples, self.fills_first_step,
            fill, initialize, n_rule, n_new, n_add,
        )  # fmt: skip
        keys = rng.random((n_rep, self.n_samples)) if n_rep else np.empty((0, self.n_samples))
        _write_update(r_s, v_s, first, n_new, n_add, keys, self.samples_mm, self.count)
        self._changed()

    # ------------------------------------------------------------------ statistics
    def estimates(self) -> RayEstimates:
        """Median, 1.48·MAD and outlier ratio of every ray (eq. 4–5, §3.3); cached."""
        if self._est is None:
            self._est = robust_estimates(self.samples_mm, self.count)
        return self._est

    def model_table(
        self, max_range_m: float, sigma_min_m: float = 0.0, min_outlier_ratio: float = 0.0
    ) -> NDArray[np.float64]:
        """Per-ray constants of eq. 6–8, ``(n_rays, 4)``: ``ρ``, ``1/(2σ²)``,
        ``log((1 − p_o)/(σ√(2π)))`` and ``p_o/maxRange`` (cached until the next update), the
        table the compiled scoring of :meth:`.LocalMap.scan_log_likelihoods` reads. ``σ``
        is floored at ``max(sigma_min_m, 1 µm)``, ``p_o`` at ``min_outlier_ratio``; a ray
        without samples gives the uniform density.
        """
        key = (float(max_range_m), float(sigma_min_m), float(min_outlier_ratio))
        if self._table is not None and self._table[0] == key:
            return self._table[1]
        est = self.estimates()
        tab = np.empty((self.n_rays, 4))
        omp, sig = np.empty(self.n_rays), np.empty(self.n_rays)
        _table_rows(est.rho_m, est.sigma_m, est.outlier_ratio, est.count, max(sigma_min_m, 1e-6),
                    float(min_outlier_ratio), float(max_range_m), tab, omp, sig)  # fmt: skip
        with np.errstate(divide="ignore"):
            tab[:, 2] = np.log(omp) - np.log(sig) + np.log(_INV_SQRT_2PI)
        self._table = (key, tab)
        return tab

    def log_likelihood(
        self,
        ray_idx: ArrayLike,
        range_m: ArrayLike,
        max_range_m: float,
        *,
        sigma_min_m: float = 0.0,
        min_outlier_ratio: float = 0.0,
    ) -> NDArray[np.float64]:
        """``log p(d)`` of eq. 6–8 for readings ``range_m`` on rays ``ray_idx``.

        ``p(d) = (1 − p_o)·N(d; ρ, σ²) + p_o·U(d; 0, maxRange)``. A ray without samples knows
        nothing and gives the uniform density. ``sigma_min_m`` and ``min_outlier_ratio`` are
        optional floors (0 = the paper's model exactly) that keep a ray whose few samples
        agree to the millimetre from giving an infinitely sharp density.
        """
        est = self.estimates()
        return mixture_log_likelihood(
            est,
            np.asarray(ray_idx, dtype=np.int64),
            np.asarray(range_m, dtype=np.float64),
            max_range_m,
            sigma_min_m=sigma_min_m,
            min_outlier_ratio=min_outlier_ratio,
        )


def robust_estimates(samples_mm: NDArray[np.uint16], count: NDArray[np.integer]) -> RayEstimates:
    """Eq. 4–5 and the 3σ outlier ratio for every row of ``samples_mm`` (first ``count``
    valid), one row at a time in a compiled loop (:func:`_robust_rows`)."""
    cnt = count.astype(np.int64)
    n_rays = samples_mm.shape[0]
    rho_m, sigma_m, outlier = np.empty(n_rays), np.empty(n_rays), np.empty(n_rays)
    _robust_rows(np.ascontiguousarray(samples_mm), cnt, rho_m, sigma_m, outlier)
    return RayEstimates(rho_m=rho_m, sigma_m=sigma_m, outlier_ratio=outlier, count=cnt)


def mixture_log_likelihood(
    est: RayEstimates,
    ray_idx: NDArray[np.int64],
    range_m: NDArray[np.float64],
    max_range_m: float,
    *,
    sigma_min_m: float = 0.0,
    min_outlier_ratio: float = 0.0,
) -> NDArray[np.float64]:
    """Eq. 6–8 evaluated with precomputed :class:`RayEstimates` (see ``log_likelihood``)."""
    cnt = est.count[ray_idx]
    rho = est.rho_m[ray_idx]
    sig = np.maximum(est.sigma_m[ray_idx], sigma_min_m)
    po = np.maximum(est.outlier_ratio[ray_idx], min_outlier_ratio)
    inside = (range_m >= 0.0) & (range_m <= max_range_m)
    p_uni = np.where(inside, 1.0 / max_range_m, 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        z = (range_m - rho) / sig
        p_norm = np.where(sig > 0, _INV_SQRT_2PI / sig * np.exp(-0.5 * z * z), 0.0)
        # A zero-width Gaussian (σ = 0, no floor) is a point mass: density only on the sample.
        p_norm = np.where((sig == 0) & (range_m == rho), np.inf, p_norm)
        p = (1.0 - po) * p_norm + po * p_uni
        p = np.where(cnt > 0, p, p_uni)
        return np.log(p)


# ---------------------------------------------------------------------- compiled kernels
@jitable
def _kth_smallest(a: NDArray[np.int64], n: int, k: int) -> int:
    """The ``k``-th smallest of ``a[:n]`` (from 0), by Hoare's selection in place: afterwards
    no element after ``a[k]`` is smaller. (Numba's full sort of a long ray is several times
    slower than numpy's; the selection is not.)"""
    lo, hi = 0, n - 1
    while lo < hi:
        x, y, z = a[lo], a[(lo + hi) // 2], a[hi]
        pivot = max(min(x, y), min(max(x, y), z))  # the median of the three
        i, j = lo, hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while a[j] > pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return a[k]


@compiled
def _robust_rows(samples_mm, count, rho_m, sigma_m, outlier):  # type: ignore[no-untyped-def]
    """Fill ``rho_m`` [m] (the lower middle sample: a measured value), ``sigma_m`` [m]
    (``1.48·MAD``, the usual median of the absolute deviations) and ``outlier`` (the share
    of samples beyond ``3σ``) for every row of ``samples_mm`` [mm] (first ``count``
    valid); NaN, NaN, 0 for an empty row."""
    n = samples_mm.shape[1]
    buf = np.empty(n, dtype=np.int64)
    for r in range(samples_mm.shape[0]):
        c = count[r]
        if c <= 0:
            rho_m[r] = np.nan
            sigma_m[r] = np.nan
            outlier[r] = 0.0
            continue
        for k in range(c):
            buf[k] = samples_mm[r, k]
        mid = (c - 1) // 2
        rho = _kth_smallest(buf, c, mid)
        for k in range(c):
            buf[k] = abs(np.int64(samples_mm[r, k]) - rho)
        lo = float(_kth_smallest(buf, c, mid))
        if c % 2 == 1:
            mad = lo
        else:  # the next order statistic: the smallest after the selected one
            hi = buf[mid + 1]
            for k in range(mid + 2, c):
                hi = min(hi, buf[k])
            mad = 0.5 * (lo + float(hi))
        sig = 1.48 * mad
        n_out = 0
        for k in range(c):
            if abs(np.int64(samples_mm[r, k]) - rho) > 3.0 * sig:
                n_out += 1
        rho_m[r] = rho / 1000.0
        sigma_m[r] = sig / 1000.0
        outlier[r] = n_out / c


@compiled
def _sort_by_ray(ray, keys, val, n_rays, r_s, v_s, first):  # type: ignore[no-untyped-def]
    """The measurements ``(ray, val)`` ordered by their ``keys`` (``ray + U[0, 1)``: by ray,
    in random order within a ray) into ``r_s``, ``v_s``, and the starts of their runs of
    equal rays into ``first``; returns the number of runs, -1 when a ray is not in
    ``[0, n_rays)``. A counting sort by ray, then each ray's keys sorted (insertion sort up
    to 16, ``np.argsort`` beyond)."""
    m = ray.shape[0]
    for i in range(m):
        if ray[i] < 0 or ray[i] >= n_rays:
            return -1
    start = np.zeros(n_rays + 1, dtype=np.int64)
    for i in range(m):
        start[ray[i] + 1] += 1
    for r in range(n_rays):
        start[r + 1] += start[r]
    nxt = start[:-1].copy()
    ks = np.empty(m)
    for i in range(m):  # into the ray's bucket, in arrival order
        q = nxt[ray[i]]
        nxt[ray[i]] = q + 1
        ks[q] = keys[i]
        v_s[q] = val[i]
    for r in range(n_rays):  # each bucket by key
        lo, hi = start[r], start[r + 1]
        if hi - lo > 16:
            o = np.argsort(ks[lo:hi]) + lo
            ks[lo:hi] = ks[o]
            v_s[lo:hi] = v_s[o]
            continue
        for p in range(lo + 1, hi):
            k = ks[p]
            v = v_s[p]
            q = p
            while q > lo and ks[q - 1] > k:
                ks[q] = ks[q - 1]
                v_s[q] = v_s[q - 1]
                q -= 1
            ks[q] = k
            v_s[q] = v
    n = 0
    for r in range(n_rays):
        if start[r + 1] > start[r]:
            first[n] = start[r]
            n += 1
        for q in range(start[r], start[r + 1]):
            r_s[q] = r
    return n


@compiled
def _plan_update(  # type: ignore[no-untyped-def]
    r_s, first, count, initialized, n_samples, fills_first_step, fill, initialize, n_rule,
    n_new, n_add,
):  # fmt: skip
    """Per run ``g`` of :func:`_sort_by_ray` (ray ``r_s[first[g]]``): ``n_new`` measurements
    taken (all that fit while filling or on a first step, else ``n_rule``, the rounded
    ``u·n``), ``n_add`` of them into free slots, the rest replacing old samples; marks the
    rays ``initialized`` (unless a ``fill`` that does not ``initialize``). Returns how many
    runs replace (the rows of random keys :func:`_write_update` needs)."""
    m = r_s.shape[0]
    n_groups = first.shape[0]
    n_rep_rows = 0
    for g in range(n_groups):
        ray = r_s[first[g]]
        end = first[g + 1] if g + 1 < n_groups else m
        m_per = end - first[g]
        cnt = np.int64(count[ray])
        free = n_samples - cnt
        if fill or (fills_first_step and not initialized[ray]):
            k = min(m_per, free)
        else:
            k = min(n_rule[g], m_per)
        if initialize or not fill:
            initialized[ray] = True
        a = min(k, free)
        n_new[g] = k
        n_add[g] = a
        if k - a > 0:
            n_rep_rows += 1
    return n_rep_rows


@compiled
def _write_update(r_s, v_s, first, n_new, n_add, keys, samples_mm, count):  # type: ignore[no-untyped-def]
    """Each run's first ``n_add`` measurements into the next free slots, the next
    ``rep = n_new - n_add`` into the old slots ``[0, count)`` of the ``rep`` smallest random
    ``keys[row]`` (``row``: the run's order among those that replace; a uniformly random
    choice of the slots), and the new counts."""
    n_groups = first.shape[0]
    slots = np.empty(samples_mm.shape[1], dtype=np.int64)
    row = 0
    for g in range(n_groups):
        start = first[g]
        ray = r_s[start]
        cnt = np.int64(count[ray])
        a = n_add[g]
        for j in range(a):
            samples_mm[ray, cnt + j] = v_s[start + j]
        rep = n_new[g] - a
        if rep > 0:
            n_kept = 0  # slots[:n_kept]: the smallest keys so far, increasing
            for q in range(cnt):
                kq = keys[row, q]
                if n_kept == rep and kq >= keys[row, slots[n_kept - 1]]:
                    continue
                p = n_kept if n_kept < rep else rep - 1
                while p > 0 and keys[row, slots[p - 1]] > kq:
                    slots[p] = slots[p - 1]
                    p -= 1
                slots[p] = q
                if n_kept < rep:
                    n_kept += 1
            for j in range(rep):
                samples_mm[ray, slots[j]] = v_s[start + a + j]
            row += 1
        count[ray] = np.uint16(cnt + a)


@compiled
def _table_rows(  # type: ignore[no-untyped-def]
    rho_m, sigma_m, outlier, count, sigma_floor_m, min_outlier_ratio, max_range_m, table,
    one_minus_po, sigma,
):  # fmt: skip
    """Columns 0, 1 and 3 of :meth:`SampleSets.model_table` (``ρ``, ``1/(2σ²)``,
    ``p_o/maxRange``), and the floored ``σ`` and ``1 - p_o`` whose logs make column 2 (a ray
    without samples: ``σ = 1``, ``p_o = 1``, the uniform density)."""
    for r in range(rho_m.shape[0]):
        if count[r] > 0:
            sg = sigma_m[r] if sigma_m[r] >= sigma_floor_m else sigma_floor_m
            po = outlier[r] if outlier[r] >= min_outlier_ratio else min_outlier_ratio
            table[r, 0] = rho_m[r]
        else:
            sg = 1.0
            po = 1.0
            table[r, 0] = 0.0
        sigma[r] = sg
        one_minus_po[r] = 1.0 - po
        table[r, 1] = 0.5 / (sg * sg)
        table[r, 3] = po / max_range_m
