"""Simulated 2-D laser scanners: Hokuyo URG-04LX and SICK LMS200 (docs/architecture.md §4).

A :class:`Lidar` casts every beam of a scan exactly against the world's geometry
(:mod:`dynmap_sim.sensors.raycast`) and then applies a seeded noise model. The presets follow
the datasheets and every figure can be overridden (:func:`make_lidar`).

Noise model (all random draws come from the ``numpy.random.Generator`` passed to
:meth:`Lidar.scan`; nothing is global). For a beam whose true range is ``r`` (the distance to
the first surface it hits):

1. **Range noise** — Gaussian, ``sigma(r) = max(sigma_m, sigma_rel * r)``. The URG-04LX
   datasheet gives "±10 mm up to 1 m, 1 % of the range beyond": the preset takes these bounds
   as one standard deviation (``sigma_m = 0.01``, ``sigma_rel = 0.01``). The LMS200 (mm mode)
   has ``sigma_m = 0.005`` and a *systematic* error of up to ±15 mm: a fixed per-beam bias,
   uniform in ``±systematic_m``, drawn once when the sensor is built (``bias_seed``), i.e. a
   property of the physical unit that stays the same across runs.
2. **Mixed pixels** — where a beam's true range differs from a neighbour's by more than
   ``mixed_jump_m`` the spot straddles an edge; with probability ``p_mixed`` such a beam reads
   a range uniformly between the two surfaces.
3. **Max-range dropouts** — with probability ``p_dropout`` a beam that hit something returns
   nothing (``+inf``), e.g. black or specular surfaces.
4. **Spurious short returns** — with probability ``p_short`` a beam that hit something reads a
   range uniform in ``[range_min, r]`` (dust, a passing hand; the "short" term of the beam
   model).
5. **Invalid readings** — with probability ``p_invalid`` a beam that hit something reads
   ``NaN``. This is **0 by default**: Gymnasium's ``Box.contains`` rejects NaN, so
   ``check_env`` would fail on an observation holding one.

Events 3-5 are mutually exclusive per beam (one uniform draw per beam is split into disjoint
intervals), so each happens with exactly its probability, and they override a mixed pixel.

Readings follow REP-117: ``+inf`` no return within ``range_max``, ``-inf`` a return closer than
``range_min``, ``NaN`` invalid. The truth labels (:class:`LidarReading` ``beam_object``,
``beam_class``) describe what each beam geometrically hits, before noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.se2 import compose
from dynmap_sim.sensors.raycast import SegmentCache, beam_directions, cast_scan, cast_scans
from dynmap_sim.types import LaserSpec

FloatArray = NDArray[np.float64]


class GeometryLike(Protocol):
    """What the lidar reads from the world (``dynmap_sim.world.geometry.GeometryView``)."""

    segments: FloatArray
    segment_object: NDArray[np.int32]
    segment_class: NDArray[np.int8]
    circles: FloatArray
    circle_object: NDArray[np.int32]
    circle_class: NDArray[np.int8]
    static_version: int


@dataclass(frozen=True)
class LidarNoise:
    """Parameters of the noise model (see the module docstring); probabilities per beam."""

    sigma_m: float = 0.01
    sigma_rel: float = 0.01
    systematic_m: float = 0.0
    p_dropout: float = 0.002
    p_short: float = 0.001
    p_mixed: float = 0.5
    mixed_jump_m: float = 0.15
    p_invalid: float = 0.0

    def __post_init__(self) -> None:
        for name in ("sigma_m", "sigma_rel", "systematic_m", "mixed_jump_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"LidarNoise.{name} must be finite and >= 0, got {v!r}")
        for name in ("p_dropout", "p_short", "p_mixed", "p_invalid"):
            v = getattr(self, name)
            if not (0.0 <= v <= 1.0):
                raise ValueError(f"LidarNoise.{name} must be a probability in [0, 1], got {v!r}")
        if self.p_dropout + self.p_short + self.p_invalid > 1.0:
            raise ValueError("LidarNoise: p_dropout + p_short + p_invalid must be <= 1")


#: Noise-free model (for exact-geometry tests and ground-truth scans).
NOISELESS = LidarNoise(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.15, 0.0)

_URG_STEP = 2.0 * math.pi / 1024.0


def _urg04lx(**over: Any) -> tuple[LaserSpec, LidarNoise]:
    spec = LaserSpec(
        name="urg-04lx",
        n_beams=683,
        # Datasheet: -2.0862 .. +2.0923 rad in steps of 360/1024 deg, 683 readings. Those three
        # figures disagree by one step (681 steps span 4.1785 rad); we keep 683 beams from
        # -2.0862 rad, so the last beam points at +2.0985 rad.
        angle_min_rad=-2.0862,
        angle_increment_rad=_URG_STEP,
        range_min_m=0.02,
        range_max_m=5.6,
        scan_period_s=0.1,
        time_increment_s=0.1 / 1024.0,
    )
    return spec, LidarNoise(sigma_m=0.01, sigma_rel=0.01)


def _lms200(beams: int = 361, mode: str = "mm", **over: Any) -> tuple[LaserSpec, LidarNoise]:
    if beams not in (181, 361):
        raise ValueError(f"lms200: beams must be 181 or 361, got {beams!r}")
    if mode not in ("mm", "cm"):
        raise ValueError(f"lms200: mode must be 'mm' (8.19 m) or 'cm' (81.9 m), got {mode!r}")
    inc = math.pi / (beams - 1)
    # The mirror turns at 75 Hz (13.3 ms); 0.5 deg scans interleave two turns (26.7 ms), and
    # the serial link limits delivery: 361 x 2 bytes at 38.4 kbaud is about 0.2 s per scan.
    spec = LaserSpec(
        name="lms200",
        n_beams=beams,
        angle_min_rad=-math.pi / 2.0,
        angle_increment_rad=inc,
        range_min_m=0.0,
        range_max_m=8.19 if mode == "mm" else 81.9,
        scan_period_s=0.2,
        time_increment_s=(1.0 / 75.0) * inc / (2.0 * math.pi),  # mirror at 75 Hz
    )
    noise = (
        LidarNoise(sigma_m=0.005, sigma_rel=0.0, systematic_m=0.015)
        if mode == "mm"
        else LidarNoise(sigma_m=0.05, sigma_rel=0.0, systematic_m=0.04)
    )
    return spec, noise


PRESETS = ("urg-04lx", "lms200")


def make_lidar(
    sensor: str = "urg-04lx",
    *,
    mount_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    noise: LidarNoise | dict[str, float] | None = None,
    bias_seed: int = 0,
    backend: str = "numpy",
    **overrides: Any,
) -> Lidar:
    """A :class:`Lidar` from a preset name, with overrides.

    ``sensor`` is ``"urg-04lx"`` or ``"lms200"``. For the LMS200, ``beams`` (181 or 361) and
    ``mode`` (``"mm"``: 8.19 m, ``"cm"``: 81.9 m) select the variant. Any
    :class:`~dynmap_sim.types.LaserSpec` field (``n_beams``, ``range_max_m``, ...) may be
    overridden by keyword; ``noise`` is a :class:`LidarNoise` or a dict of fields to change in
    the preset's noise model. ``backend`` is one of :data:`LIDAR_BACKENDS`: ``"numpy"``,
    ``"numba"`` (extra ``fast``: the compiled ray casting of
    :mod:`~dynmap_sim.sensors.raycast_numba` and noise model of
    :mod:`~dynmap_sim.sensors.noise_numba`, whose readings are numpy's bit for bit) or
    ``"auto"`` (those when numba is installed, numpy's casting where the compiled one could
    not reproduce numpy's complex arithmetic).
    """
    variant = {k: overrides.pop(k) for k in ("beams", "mode") if k in overrides}
    if sensor == "urg-04lx":
        if variant:
            raise ValueError(f"urg-04lx has no variants {sorted(variant)}")
        spec, preset_noise = _urg04lx()
    elif sensor == "lms200":
        spec, preset_noise = _lms200(**variant)
    else:
        raise ValueError(f"unknown laser scanner {sensor!r}; choose one of {PRESETS}")
    fields = set(LaserSpec.__dataclass_fields__)
    bad = sorted(set(overrides) - fields)
    if bad:
        raise ValueError(f"unknown laser parameter(s) {bad}; valid: {sorted(fields)}")
    spec = replace(spec, mount_pose=tuple(float(v) for v in mount_pose), **overrides)
    if isinstance(noise, dict):
        noise = replace(preset_noise, **noise)
    return Lidar(
        spec, noise if noise is not None else preset_noise, bias_seed=bias_seed, backend=backend
    )


def cast_many(
    lidars: list[Lidar], robot_poses: list[FloatArray], geoms: list[GeometryLike]
) -> tuple[FloatArray, NDArray[np.int64]]:
    """:meth:`Lidar.cast` of each lidar from its robot pose among its geometry, as rows:
    noise-free ranges [m] and hit indices ``(len(lidars), n_beams)``; one
    :func:`~dynmap_sim.sensors.raycast.cast_scans` pass for all when they are numpy
    casters of the same beams (the same numbers as one by one)."""
    first = lidars[0]
    same = all(lid.spec == first.spec and lid._cast is cast_scan for lid in lidars)
    if len(lidars) < 2 or not same:
        casts = [lid.cast(p, g) for lid, p, g in zip(lidars, robot_poses, geoms, strict=True)]
        return np.stack([c[0] for c in casts]), np.stack([c[1] for c in casts])
    spec = first.spec
    return cast_scans(
        [lid.sensor_pose(p) for lid, p in zip(lidars, robot_poses, strict=True)],
        spec.angle_min_rad,
        spec.angle_increment_rad,
        first._cos,
        first._sin,
        spec.range_max_m,
        [lid._segments(g) for lid, g in zip(lidars, geoms, strict=True)],
        [g.circles if g.circles.shape[0] else None for g in geoms],
        first._u,
    )


@dataclass
class LidarReading:
    """One scan: REP-117 ``ranges_m`` (float32) plus ground truth per beam.

    ``true_range_m`` is the noise-free distance (``+inf`` for no hit); ``beam_object`` indexes
    ``GeometryView.object_ids`` (``-1``: nothing hit); ``beam_class`` is a
    :class:`~dynmap_sim.types.BeamClass` value (``0``: nothing hit).
    """

    ranges_m: NDArray[np.float32]
    true_range_m: FloatArray
    beam_object: NDArray[np.int32]
    beam_class: NDArray[np.int8]


#: Lidar backends: ``numpy`` (casting and noise), ``numba`` (extra ``fast``: compiled
#: casting, noise model and people's step), ``auto`` (the compiled ones when numba is
#: installed and the compiled casting reproduces numpy's complex arithmetic on this install,
#: :func:`~dynmap_sim.numpy_complex.numpy_complex_mode`, else numpy's casting; the
#: compiled noise and people's step whenever numba is installed). The compiled noise and
#: people's step give numpy's numbers bit for bit on every install, the casting wherever
#: that mode is known (``numba`` casts in the fused mode elsewhere: numpy's ranges to
#: rounding), so ``auto`` has numpy's numbers on every install.
LIDAR_BACKENDS = ("numpy", "numba", "auto")


def _caster(backend: str) -> Any:
    """The casting function of ``backend``: :func:`~dynmap_sim.sensors.raycast.cast_scan`
    or its compiled twin (see :data:`LIDAR_BACKENDS`)."""
    if backend == "numpy":  # (numba is not even imported)
        return cast_scan
    from dynmap_sim.jit import kernel_backend
    from dynmap_sim.numpy_complex import numpy_complex_mode
    from dynmap_sim.sensors import raycast_numba

    if backend == "auto":
        exact = kernel_backend("auto") is not None and numpy_complex_mode() is not None
        return raycast_numba.cast_scan_numba if exact else cast_scan
    if not raycast_numba.numba_available():
        raise ValueError('lidar backend "numba" needs numba: pip install "dynmap-sim[fast]"')
    return raycast_numba.cast_scan_numba


def _compiled_noise(backend: str) -> Any:
    """The compiled noise of one scan for ``backend`` (numba; auto when installed:
    :func:`dynmap_sim.jit.kernel_backend`), else None (numpy's)."""
    if backend == "numpy":  # (numba is not even imported)
        return None
    from dynmap_sim.jit import kernel_backend

    if kernel_backend(backend) is None:
        return None
    from dynmap_sim.sensors.noise_numba import noise_scan

    return noise_scan


class Lidar:
    """A laser scanner mounted on the robot at ``spec.mount_pose`` (``base_link`` frame)."""

    def __init__(
        self, spec: LaserSpec, noise: LidarNoise, bias_seed: int = 0, backend: str = "numpy"
    ) -> None:
        if backend not in LIDAR_BACKENDS:
            raise ValueError(f"lidar backend must be one of {LIDAR_BACKENDS}, got {backend!r}")
        self._cast = _caster(backend)
        # the compiled noise of one scan (numba; auto when installed), None: numpy's
        self._noise_scan: Any = _compiled_noise(backend)
        self.backend = backend
        if spec.n_beams < 2:
            raise ValueError(f"a laser scanner needs at least 2 beams, got {spec.n_beams}")
        if not (0.0 <= spec.range_min_m < spec.range_max_m and math.isfinite(spec.range_max_m)):
            raise ValueError(
                f"need 0 <= range_min_m < range_max_m < inf, got "
                f"{spec.range_min_m}, {spec.range_max_m}"
            )
        if not spec.angle_increment_rad > 0.0:
            raise ValueError("angle_increment_rad must be > 0")
        if spec.n_beams * spec.angle_increment_rad > 2.0 * math.pi + 1e-9:
            raise ValueError("the beams span more than a full turn")
        self.spec = spec
        self.noise = noise
        brng = np.random.default_rng(np.random.SeedSequence([bias_seed, 117]))
        self._bias_m = brng.uniform(-1.0, 1.0, spec.n_beams) * noise.systematic_m
        self._cos, self._sin = beam_directions(
            spec.angle_min_rad, spec.angle_increment_rad, spec.n_beams
        )
        self._u = self._cos + 1j * self._sin
        self._cache_key: tuple[int, np.ndarray] | None = None
        self._cache: SegmentCache | None = None
        self._labels_key: tuple[np.ndarray, ...] | None = None
        self._labels: tuple[NDArray[np.int32], NDArray[np.int8]] | None = None

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the broad-phase cache (rebuilt on the next scan; its per-cell
        candidate lists would only bloat checkpoints)."""
        state = self.__dict__.copy()
        state["_cache"] = None
        state["_cache_key"] = None
        if self.backend == "auto":  # resolved again where it is unpickled
            state["_noise_scan"] = None
            state["_cast"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore; a lidar pickled before the compiled noise existed uses numpy's (the
        same numbers), an ``auto`` one the compiled noise if this install has numba."""
        self.__dict__.update(state)
        self.__dict__.setdefault("_noise_scan", None)
        if self.backend == "auto":
            self._noise_scan = _compiled_noise("auto")
            self._cast = _caster("auto")

    def _segments(self, geom: GeometryLike) -> SegmentCache:
        """Broad-phase data of the segments, rebuilt when the geometry changes.

        The key holds the source array itself (not its ``id``), so a freed array's id being
        reused by another world's array cannot serve stale geometry.
        """
        key = (int(geom.static_version), geom.segments)
        ck = self._cache_key
        if ck is None or ck[0] != key[0] or ck[1] is not key[1] or self._cache is None:
            self._cache = SegmentCache.build(geom.segments)
            self._cache_key = key
        return self._cache

    def _label_tables(self, geom: GeometryLike) -> tuple[NDArray[np.int32], NDArray[np.int8]]:
        """Object index and class per hit index (segments, circles, then -1 / NONE)."""
        src = (geom.segment_object, geom.segment_class, geom.circle_object, geom.circle_class)
        lk = self._labels_key
        if (
            lk is None
            or self._labels is None
            or lk[0] is not src[0]
            or lk[1] is not src[1]
            or lk[2] is not src[2]
            or lk[3] is not src[3]
        ):
            obj = np.concatenate([geom.segment_object, geom.circle_object, [-1]]).astype(np.int32)
            cls = np.concatenate([geom.segment_class, geom.circle_class, [0]]).astype(np.int8)
            self._labels = (obj, cls)
            self._labels_key = src
        return self._labels

    def laser_pose(self, robot_pose: FloatArray) -> FloatArray:
        """The laser's pose in the map frame for a robot (``base_link``) pose."""
        return compose(np.asarray(robot_pose, dtype=np.float64), self.spec.mount_pose)

    def sensor_pose(self, robot_pose: FloatArray) -> tuple[float, float, float]:
        """The laser's pose ``(x, y, heading)`` [m, rad] in the map frame, as a tuple."""
        x, y, th = float(robot_pose[0]), float(robot_pose[1]), float(robot_pose[2])
        mx, my, myaw = self.spec.mount_pose
        if mx or my or myaw:
            c, s = math.cos(th), math.sin(th)
            x, y, th = x + c * mx - s * my, y + s * mx + c * my, th + myaw
        return x, y, th

    def cast(self, robot_pose: FloatArray, geom: GeometryLike) -> tuple[FloatArray, NDArray]:
        """Noise-free ranges [m] (``+inf``: no hit) and hit indices (see ``cast_scan``)."""
        spec = self.spec
        circles = geom.circles if geom.circles.shape[0] else None
        return self._cast(
            self.sensor_pose(robot_pose),
            spec.angle_min_rad,
            spec.angle_increment_rad,
            self._cos,
            self._sin,
            spec.range_max_m,
            self._segments(geom),
            circles,
            self._u,
        )

    def scan(
        self, robot_pose: FloatArray, geom: GeometryLike, rng: np.random.Generator
    ) -> LidarReading:
        """One noisy scan from the robot at ``robot_pose`` (map frame) with truth labels."""
        true_r, hit = self.cast(robot_pose, geom)
        return self.reading(true_r, hit, geom, rng)

    def reading(
        self,
        true_r: FloatArray,
        hit: NDArray,
        geom: GeometryLike,
        rng: np.random.Generator,
        ranges_m: NDArray[np.float32] | None = None,
    ) -> LidarReading:
        """The scan of noise-free ranges ``true_r`` and hit indices ``hit`` (of
        :meth:`cast` among ``geom``): noise from ``rng`` (or the noisy ``ranges_m`` already
        made from ``true_r``) and truth labels."""
        obj, cls = self._label_tables(geom)
        ranges = self.apply_noise(true_r, rng) if ranges_m is None else ranges_m
        return LidarReading(ranges, true_r, obj[hit], cls[hit])

    def apply_noise(
        self, true_range_m: FloatArray, rng: np.random.Generator
    ) -> NDArray[np.float32]:
        """REP-117 readings from noise-free ranges (see the module docstring for the model).

        ``true_range_m`` has shape ``(..., n_beams)`` (a batch of scans is allowed; its draws
        all come from ``rng``).
        """
        r = np.asarray(true_range_m, dtype=np.float64)
        if r.shape[-1] != self.spec.n_beams:
            raise ValueError(f"expected (..., {self.spec.n_beams}) ranges, got shape {r.shape}")
        if self._noise_scan is not None and r.ndim == 1:
            # the numba backend: the same model in compiled loops (the same numbers)
            spec = self.spec
            return self._noise_scan(
                np.ascontiguousarray(r),
                rng,
                self._bias_m,
                self.noise,
                spec.range_min_m,
                spec.range_max_m,
            )
        return self._noise(r.reshape(-1, r.shape[-1]), [rng]).reshape(r.shape)

    def apply_noise_rows(
        self, true_range_m: FloatArray, rngs: list[np.random.Generator]
    ) -> NDArray[np.float32]:
        """:meth:`apply_noise` of each row of ``true_range_m`` ``(S, n_beams)`` with its own
        generator ``rngs[i]``: row ``i`` reads what ``apply_noise(true_range_m[i], rngs[i])``
        gives (the same draws in the same order), the arithmetic done once for all rows."""
        r = np.asarray(true_range_m, dtype=np.float64)
        if r.ndim != 2 or r.shape != (len(rngs), self.spec.n_beams):
            raise ValueError(
                f"expected ({len(rngs)}, {self.spec.n_beams}) ranges, got shape {r.shape}"
            )
        return self._noise(r, rngs)

    def _noise(self, r: FloatArray, rngs: list[np.random.Generator]) -> NDArray[np.float32]:
        """The noise model on ranges ``r`` ``(S, n_beams)`` whose rows fall into
        ``len(rngs)`` equal groups of consecutive rows, group ``g`` drawing from ``rngs[g]``
        (in the order one :meth:`apply_noise` of that group alone draws)."""
        nz = self.noise
        spec = self.spec
        hit = r <= spec.range_max_m
        # the hits' ranges, NaN elsewhere (also the mixed pixels' edge test below)
        rn = np.where(hit, r, np.nan) if nz.p_mixed > 0.0 or nz.sigma_rel else r
        if not nz.sigma_rel:
            sigma = nz.sigma_m
        elif nz.sigma_m > 0.0:
            # fmax skips the NaN of no-hit beams: sigma_m there, as max(sigma_rel * 0, sigma_m)
            sigma = np.fmax(nz.sigma_rel * rn, nz.sigma_m)
        else:
            sigma = np.maximum(nz.sigma_rel * np.where(hit, r, 0.0), nz.sigma_m)
        if len(rngs) == 1:
            out = rngs[0].standard_normal(r.shape)
        else:
            out = _row_draws(rngs, r.shape, "standard_normal")
        out *= sigma
        out += r + self._bias_m if nz.systematic_m else r  # inf stays inf
        flat_out = out.reshape(-1)
        flat_r = r.reshape(-1)
        group_size = r.size // len(rngs)  # flat beams per group
        if nz.p_mixed > 0.0:
            # depth discontinuities between neighbours i, i+1 (NaN for no-hit beams: no edge)
            # (NaN arithmetic and comparisons are quiet: no errstate needed)
            edge = np.abs(rn[:, 1:] - rn[:, :-1]) > nz.mixed_jump_m
            e = edge.ravel().nonzero()[0]
            if e.size:
                # flat index of the left beam of each edge (rows are n_beams long)
                left = e + e // (spec.n_beams - 1) if r.shape[0] > 1 else e
                # each group's edges with its generator (its draws in a lone group's order)
                for g, left_g in _by_group(left.tolist(), group_size):
                    _mixed_pixels(flat_out, flat_r, left_g, rngs[g], nz.p_mixed)
        # one uniform per beam picks at most one of the rare events (disjoint intervals)
        p1 = nz.p_dropout
        p2 = p1 + nz.p_short
        p3 = p2 + nz.p_invalid
        if p3 > 0.0:
            u = rngs[0].random(r.shape) if len(rngs) == 1 else _row_draws(rngs, r.shape, "random")
            rare = ((u < p3) & hit).ravel().nonzero()[0]
            if rare.size:
                flat_u = u.reshape(-1)
                for g, rare_g in _by_group(rare.tolist(), group_size):
                    _rare_events(flat_out, flat_r, flat_u, rare_g, rngs[g], p1, p2, spec)
        out[out < spec.range_min_m] = -np.inf
        out[out > spec.range_max_m] = np.inf
        return out.astype(np.float32)


def _mixed_pixels(
    out: FloatArray, r: FloatArray, left: list[int], rng: np.random.Generator, p_mixed: float
) -> None:
    """Mixed pixels of one scan (true ranges ``r``, readings ``out``) at the edges between
    beams ``left[k]`` and ``left[k] + 1``: each edge's two beams (all left beams, then all
    right beams) are picked with probability ``p_mixed`` and read a range uniformly between
    the two surfaces. The draws and the arithmetic of the array form, one beam at a time
    (the edges of a scan are a handful)."""
    beams = left + [b + 1 for b in left]
    others = [b + 1 for b in left] + left
    pick = (rng.random(len(beams)) < p_mixed).tolist()
    chosen = [(b, o) for b, o, p in zip(beams, others, pick, strict=True) if p]
    w = rng.random(len(chosen)).tolist()
    for (b, o), wk in zip(chosen, w, strict=True):
        rb = r.item(b)
        out[b] = rb + wk * (r.item(o) - rb)


def _rare_events(
    out: FloatArray,
    r: FloatArray,
    u: FloatArray,
    rare: list[int],
    rng: np.random.Generator,
    p1: float,
    p2: float,
    spec: LaserSpec,
) -> None:
    """Dropouts (``u < p1``), short returns (``u < p2``) and invalid readings of the beams
    ``rare`` of one scan (true ranges ``r``, readings ``out``, uniforms ``u``): one short
    range drawn per rare beam, as the array form draws them, and the same arithmetic."""
    rmin = spec.range_min_m
    short = rng.random(len(rare)).tolist()
    for i, sk in zip(rare, short, strict=True):
        ui = u.item(i)
        out[i] = math.inf if ui < p1 else (rmin + sk * (r.item(i) - rmin) if ui < p2 else math.nan)


def _by_group(beams: list[int], group_size: int) -> list[tuple[int, list[int]]]:
    """Ascending flat ``beams`` split by group (``group_size`` flat beams each): ``(group,
    its beams)`` for each group that has some, in group order."""
    out: list[tuple[int, list[int]]] = []
    for b in beams:
        g = b // group_size
        if out and out[-1][0] == g:
            out[-1][1].append(b)
        else:
            out.append((g, [b]))
    return out


def _row_draws(rngs: list[np.random.Generator], shape: tuple[int, ...], kind: str) -> FloatArray:
    """An array of ``shape`` of ``kind`` draws (``"standard_normal"`` or ``"random"``) whose
    rows fall into ``len(rngs)`` equal groups, group ``g`` drawn by ``rngs[g]`` in one call."""
    out = np.empty(shape)
    rows = shape[0] // len(rngs)
    for g, rng in enumerate(rngs):
        getattr(rng, kind)(out=out[g * rows : (g + 1) * rows])
    return out
