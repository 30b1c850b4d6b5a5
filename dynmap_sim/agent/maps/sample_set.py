"""Dynamic sample sets, vectorized over many rays (Biber & Duckett 2009, §3.1–3.3, §4.2).

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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.maps.sample_set_numba import (
    numba_available,
    robust_rows,
    table_kernel,
    update_kernels,
)

#: Largest storable range [mm] (uint16); also the sort key of empty slots.
MAX_RANGE_MM = 65535

#: 1/sqrt(2π)
_INV_SQRT_2PI = 0.3989422804014327

#: Up to this many measurements a ray on average, the numba update sorts them with its
#: bucket sort (faster for the few of an online step), beyond with numpy's ``argsort``
#: (faster for the hundreds of an offline step); the same order either way.
_BUCKET_SORT_PER_RAY = 16


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
        backend: str = "auto",
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

        ``backend`` (:data:`dynmap_sim.jit.KERNEL_BACKENDS`): with ``"numba"`` (``"auto"``
        when installed) the bookkeeping runs in compiled kernels
        (:func:`.sample_set_numba.update_kernels`) between the same random draws and sorts:
        the same samples.
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
        kernels = update_kernels(backend)
        if kernels is not None:  # (the sort kernel checks the rays)
            # Random order within each ray: "randomly chosen samples from M".
            keys = ray + rng.random(m)  # by ray, random within a ray
            self._update_kernels(kernels, ray, keys, val, rng, fill, initialize)
            return
        if ray.min() < 0 or ray.max() >= self.n_rays:
            raise ValueError("ray index out of range")
        keys = ray + rng.random(m)
        order = np.argsort(keys)
        r_s = ray[order]
        v_s = val[order]
        # Runs of equal rays in the sorted order (what np.unique would return, without a sort).
        starts = np.empty(m, dtype=bool)
        starts[0] = True
        np.not_equal(r_s[1:], r_s[:-1], out=starts[1:])
        first = np.flatnonzero(starts)
        uniq = r_s[first]
        m_per = np.diff(first, append=m)
        g = np.repeat(np.arange(uniq.size), m_per)
        rank = np.arange(m) - first[g]

        cnt = self.count[uniq].astype(np.int64)
        free = self.n_samples - cnt
        first = ~self.initialized[uniq] & self.fills_first_step
        if fill:
            n_new = np.minimum(m_per, free)
        else:
            n_new = np.where(
                first, np.minimum(m_per, free), np.minimum(self._n_new(uniq.size, rng), m_per)
            )
        if initialize or not fill:
            self.initialized[uniq] = True
        n_add = np.minimum(n_new, free)
        n_rep = n_new - n_add

        slot = cnt[g] + rank  # filling: next free slot
        rep_rows = np.flatnonzero(n_rep > 0)
        if rep_rows.size:
            # Random permutation of each such ray's *old* slots [0, cnt): remove the first n_rep.
            keys = rng.random((rep_rows.size, self.n_samples))
            keys[np.arange(self.n_samples)[None, :] >= cnt[rep_rows, None]] = 2.0
            perm = np.argsort(keys, axis=1)
            row_of_group = np.full(uniq.size, -1, dtype=np.int64)
            row_of_group[rep_rows] = np.arange(rep_rows.size)
            is_rep = (rank >= n_add[g]) & (rank < n_new[g])
            pr = row_of_group[g[is_rep]]
            slot[is_rep] = perm[pr, rank[is_rep] - n_add[g[is_rep]]]
        keep = rank < n_new[g]
        self.samples_mm[uniq[g[keep]], slot[keep]] = v_s[keep]
        self.count[uniq] = (cnt + n_add).astype(np.uint16)
        self._changed()

    def _update_kernels(
        self,
        kernels: tuple,
        ray: NDArray[np.int64],
        keys: NDArray[np.float64],
        val: NDArray[np.uint16],
        rng: np.random.Generator,
        fill: bool,
        initialize: bool,
    ) -> None:
        """:meth:`update` after its sort keys, with :func:`.sample_set_numba.update_kernels`:
        the measurements in the order of the numpy code's ``argsort`` of ``keys`` (a compiled
        bucket sort; ``argsort`` itself if two keys are equal), the same random draws in the
        same order (``u·n`` rounding, then the keys of the slots to replace), the keys put
        in the order of the numpy code's ``argsort`` by the kernel. (A ray out of range raises
        here, after the draw of ``keys``; the numpy code raises before it.)"""
        sort_by_ray, ray_runs, plan_update, write_update = kernels
        m = ray.size
        r_s = np.empty(m, dtype=np.int64)
        v_s = np.empty(m, dtype=np.uint16)
        first = np.empty(m, dtype=np.int64)
        if m <= _BUCKET_SORT_PER_RAY * self.n_rays:  # a few a ray (online): the kernel
            n_runs = sort_by_ray(ray, keys, val, self.n_rays, r_s, v_s, first)
        elif ray.min() < 0 or ray.max() >= self.n_rays:  # many (offline): numpy's argsort
            n_runs = -2
        else:
            n_runs = -1
        if n_runs == -2:
            raise ValueError("ray index out of range")
        if n_runs < 0:  # equal keys, or many a ray: numpy's order
            order = np.argsort(keys)
            r_s = ray[order]
            v_s = val[order]
            n_runs = ray_runs(r_s, first)
        first = first[:n_runs]
        n_groups = first.size
        n_rule = np.zeros(n_groups, dtype=np.int64) if fill else self._n_new(n_groups, rng)
        n_new = np.empty(n_groups, dtype=np.int64)
        n_add = np.empty(n_groups, dtype=np.int64)
        rep_cnt = np.empty(n_groups, dtype=np.int64)
        n_rep = plan_update(
            r_s, first, self.count, self.initialized, self.n_samples,
            self.fills_first_step, fill, initialize, n_rule, n_new, n_add, rep_cnt,
        )  # fmt: skip
        keys = rng.random((n_rep, self.n_samples)) if n_rep else np.empty((0, self.n_samples))
        write_update(r_s, v_s, first, n_new, n_add, keys, self.samples_mm, self.count)
        self._changed()

    def update_m(
        self,
        ray_idx: ArrayLike,
        range_m: ArrayLike,
        rng: np.random.Generator,
        *,
        fill: bool = False,
    ) -> None:
        """:meth:`update` with ranges in metres."""
        self.update(ray_idx, to_mm(range_m), rng, fill=fill)

    # ------------------------------------------------------------------ statistics
    def estimates(self) -> RayEstimates:
        """Median, 1.48·MAD and outlier ratio of every ray (eq. 4–5, §3.3); cached."""
        if self._est is None:
            self._est = robust_estimates(self.samples_mm, self.count)
        return self._est

    def model_table(
        self,
        max_range_m: float,
        sigma_min_m: float = 0.0,
        min_outlier_ratio: float = 0.0,
        backend: str = "auto",
    ) -> NDArray[np.float64]:
        """Per-ray constants of eq. 6–8, ``(n_rays, 4)``: ``ρ``, ``1/(2σ²)``,
        ``log((1 − p_o)/(σ√(2π)))`` and ``p_o/maxRange`` (cached until the next update).

        Used by :func:`table_log_likelihood`, the fast path of the localizer. ``σ`` is
        floored at ``max(sigma_min_m, 1 µm)``. ``backend`` ``"numba"`` (``"auto"`` when
        installed): the arithmetic but the logs in a compiled loop
        (:func:`.sample_set_numba.table_kernel`), the same values.
        """
        key = (float(max_range_m), float(sigma_min_m), float(min_outlier_ratio))
        if self._table is not None and self._table[0] == key:
            return self._table[1]
        est = self.estimates()
        kernel = table_kernel(backend)
        if kernel is not None:
            tab = np.empty((self.n_rays, 4))
            omp, sig = np.empty(self.n_rays), np.empty(self.n_rays)
            kernel(est.rho_m, est.sigma_m, est.outlier_ratio, est.count, max(sigma_min_m, 1e-6),
                   float(min_outlier_ratio), float(max_range_m), tab, omp, sig)  # fmt: skip
            with np.errstate(divide="ignore"):
                tab[:, 2] = np.log(omp) - np.log(sig) + np.log(_INV_SQRT_2PI)
            self._table = (key, tab)
            return tab
        has = est.count > 0
        sig = np.where(has, np.maximum(np.nan_to_num(est.sigma_m), max(sigma_min_m, 1e-6)), 1.0)
        po = np.where(has, np.maximum(est.outlier_ratio, min_outlier_ratio), 1.0)
        tab = np.empty((self.n_rays, 4))
        tab[:, 0] = np.where(has, est.rho_m, 0.0)
        tab[:, 1] = 0.5 / (sig * sig)
        with np.errstate(divide="ignore"):
            tab[:, 2] = np.log(1.0 - po) - np.log(sig) + np.log(_INV_SQRT_2PI)
        tab[:, 3] = po / max_range_m
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


def robust_estimates(
    samples_mm: NDArray[np.uint16], count: NDArray[np.integer], backend: str = "auto"
) -> RayEstimates:
    """Eq. 4–5 and the 3σ outlier ratio for every row of ``samples_mm`` (first ``count`` valid).

    ``backend`` ``"numba"`` (extra ``fast``; ``"auto"``: when installed and the rows are
    short) computes the identical values in a compiled loop (:mod:`.sample_set_numba`),
    ``"numpy"`` vectorized.
    """
    n_rays, n = samples_mm.shape
    cnt = count.astype(np.int64)
    if backend not in ("auto", "numpy", "numba"):
        raise ValueError(f'backend must be "auto", "numpy" or "numba", got {backend!r}')
    if backend == "numba" or (backend == "auto" and n <= 16 and numba_available()):
        rho_m, sigma_m, outlier = robust_rows(samples_mm, cnt)
        return RayEstimates(rho_m=rho_m, sigma_m=sigma_m, outlier_ratio=outlier, count=cnt)
    valid = np.arange(n)[None, :] < cnt[:, None]
    s = np.where(valid, samples_mm.astype(np.int32), MAX_RANGE_MM + 1)
    s.sort(axis=1)
    rows = np.arange(n_rays)
    has = cnt > 0
    mid = np.maximum(cnt - 1, 0) // 2  # lower middle: always a measured value
    rho_mm = s[rows, mid]
    absdev = np.abs(samples_mm.astype(np.int32) - rho_mm[:, None])
    dev = np.where(valid, absdev, np.iinfo(np.int32).max)
    dev.sort(axis=1)
    lo = dev[rows, mid].astype(np.float64)
    hi = dev[rows, np.minimum(cnt // 2, n - 1)].astype(np.float64)
    mad_mm = np.where(cnt % 2 == 1, lo, 0.5 * (lo + hi))  # MAD is a scale: the usual median
    sigma_mm = 1.48 * mad_mm
    n_out = np.sum(valid & (absdev > 3.0 * sigma_mm[:, None]), axis=1)
    outlier = np.where(has, n_out / np.maximum(cnt, 1), 0.0)
    rho_m = np.where(has, rho_mm / 1000.0, np.nan)
    sigma_m = np.where(has, sigma_mm / 1000.0, np.nan)
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


def table_log_likelihood(
    table: NDArray[np.float64],
    ray_idx: NDArray[np.int64],
    range_m: NDArray[np.float64],
    max_range_m: float,
) -> NDArray[np.float64]:
    """Eq. 6–8 from a :meth:`SampleSets.model_table` (one gather, few temporaries)."""
    t = table[ray_idx]
    z = range_m - t[:, 0]
    p = np.exp(t[:, 2] - z * z * t[:, 1])
    p += np.where((range_m >= 0.0) & (range_m <= max_range_m), t[:, 3], 0.0)
    with np.errstate(divide="ignore"):
        return np.log(p)
