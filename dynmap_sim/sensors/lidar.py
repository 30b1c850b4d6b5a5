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
The arithmetic between the draws runs in compiled loops; the draws are numpy's, from the
generator passed in (so the same seed gives the same readings).

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

from dynmap_sim.jit import compiled
from dynmap_sim.se2 import compose
from dynmap_sim.sensors.raycast import beam_directions, cast_scan
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
    **overrides: Any,
) -> Lidar:
    """A :class:`Lidar` from a preset name, with overrides.

    ``sensor`` is ``"urg-04lx"`` or ``"lms200"``. For the LMS200, ``beams`` (181 or 361) and
    ``mode`` (``"mm"``: 8.19 m, ``"cm"``: 81.9 m) select the variant. Any
    :class:`~dynmap_sim.types.LaserSpec` field (``n_beams``, ``range_max_m``, ...) may be
    overridden by keyword; ``noise`` is a :class:`LidarNoise` or a dict of fields to change in
    the preset's noise model.
    """
    if "backend" in overrides:
        raise ValueError(
            "the lidar option 'backend' is gone: the compiled ray caster and noise model are "
            "the only ones (remove the option)"
        )
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
    return Lidar(spec, noise if noise is not None else preset_noise, bias_seed=bias_seed)


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


class Lidar:
    """A laser scanner mounted on the robot at ``spec.mount_pose`` (``base_link`` frame)."""

    def __init__(self, spec: LaserSpec, noise: LidarNoise, bias_seed: int = 0) -> None:
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
        self._labels_key: tuple[np.ndarray, ...] | None = None
        self._labels: tuple[NDArray[np.int32], NDArray[np.int8]] | None = None

    def _label_tables(self, geom: GeometryLike) -> tuple[NDArray[np.int32], NDArray[np.int8]]:
        """Object index and class per hit index (segments, circles, then -1 / NONE)."""
        src = (geom.segment_object, geom.segment_class, geom.circle_object, geom.circle_class)
        lk = self._labels_key
        if (
            lk is None
            or self._labels is None
            or any(a is not b for a, b in zip(lk, src, strict=True))
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
        return cast_scan(
            self.sensor_pose(robot_pose),
            spec.angle_min_rad,
            spec.angle_increment_rad,
            self._cos,
            self._sin,
            spec.range_max_m,
            geom.segments,
            geom.circles if geom.circles.shape[0] else None,
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

        ``true_range_m`` has shape ``(..., n_beams)``; a batch of scans is noised scan after
        scan, all draws from ``rng``.
        """
        r = np.asarray(true_range_m, dtype=np.float64)
        n = self.spec.n_beams
        if r.shape[-1:] != (n,):
            raise ValueError(f"expected (..., {n}) ranges, got shape {r.shape}")
        rows = np.ascontiguousarray(r.reshape(-1, n))
        out = np.empty(rows.shape, dtype=np.float32)
        for i in range(rows.shape[0]):
            out[i] = _noise_scan(rows[i], rng, self._bias_m, self.noise, self.spec)
        return out.reshape(r.shape)


@compiled
def _range_noise(r, out, bias, sigma, r_max, jump, left):  # type: ignore[no-untyped-def]
    """Range noise in place: ``out`` (standard normal draws) := ``r + bias + out * s`` with
    ``s = max(sigma_rel * r, sigma_m)`` (``r`` counting 0 for no hit; ``sigma = (sigma_m,
    sigma_rel)``), and the left beams of the depth edges (``|r[i + 1] - r[i]| > jump``, both
    hit) into ``left`` (``jump < 0``: none). Returns the number of edges."""
    sigma_m, sigma_rel = sigma[0], sigma[1]
    n = r.shape[0]
    for i in range(n):
        ri = r[i]
        s = max(sigma_rel * (ri if ri <= r_max else 0.0), sigma_m)
        out[i] = ri + bias[i] + out[i] * s
    n_edges = 0
    if jump >= 0.0:
        for i in range(n - 1):
            a, b = r[i], r[i + 1]
            if a <= r_max and b <= r_max and abs(b - a) > jump:
                left[n_edges] = i
                n_edges += 1
    return n_edges


@compiled
def _mixed_pixels(r, out, left, n_edges, pick, p_mixed, w):  # type: ignore[no-untyped-def]
    """Mixed pixels: each edge's two beams (all left beams, then all right beams) whose
    ``pick`` draw is below ``p_mixed`` read ``r[b] + w (r[o] - r[b])`` (``o`` the beam across
    the edge, ``w`` the next weight draw). Returns the number of weights used."""
    m = 0
    for j in range(2 * n_edges):
        if pick[j] < p_mixed:
            b = left[j] if j < n_edges else left[j - n_edges] + 1
            o = b + 1 if j < n_edges else b - 1
            out[b] = r[b] + w[m] * (r[o] - r[b])
            m += 1
    return m


@compiled
def _rare_beams(r, u, p_any, r_max):  # type: ignore[no-untyped-def]
    """The number of beams that hit with ``u < p_any`` (a rare event each)."""
    m = 0
    for i in range(r.shape[0]):
        if r[i] <= r_max and u[i] < p_any:
            m += 1
    return m


@compiled
def _finish(r, out, u, short, p, r_min, r_max, res):  # type: ignore[no-untyped-def]
    """Rare events of the beams that hit (``u < p[0]``: dropout ``+inf``; ``< p[1]``: a
    short return ``r_min + short (r - r_min)``, one ``short`` draw per rare beam in order;
    ``< p[2]``: NaN), then REP-117 (``-inf`` below ``r_min``, ``+inf`` beyond ``r_max``)
    into the float32 readings ``res``."""
    j = 0
    for i in range(out.shape[0]):
        v = out[i]
        if u.shape[0] and r[i] <= r_max and u[i] < p[2]:
            if u[i] < p[0]:
                v = math.inf
            elif u[i] < p[1]:
                v = r_min + short[j] * (r[i] - r_min)
            else:
                v = math.nan
            j += 1
        if v < r_min:
            v = -math.inf
        elif v > r_max:
            v = math.inf
        res[i] = v


_EMPTY = np.zeros(0)


def _noise_scan(
    r: FloatArray,
    rng: np.random.Generator,
    bias: FloatArray,
    nz: LidarNoise,
    spec: LaserSpec,
) -> NDArray[np.float32]:
    """The noisy readings of one scan's true ranges ``r`` ``(n,)`` (float64, C-contiguous),
    drawn from ``rng``; ``bias`` is the lidar's per-beam systematic error."""
    n = r.shape[0]
    r_max = float(spec.range_max_m)
    out = rng.standard_normal(n)
    left = np.empty(n, dtype=np.int64)
    sigma = np.array([nz.sigma_m, nz.sigma_rel])
    jump = float(nz.mixed_jump_m) if nz.p_mixed > 0.0 else -1.0
    n_edges = _range_noise(r, out, bias, sigma, r_max, jump, left)
    if n_edges:
        pick = rng.random(2 * n_edges)
        w = rng.random(int((pick < nz.p_mixed).sum()))
        _mixed_pixels(r, out, left, n_edges, pick, float(nz.p_mixed), w)
    p1 = nz.p_dropout
    p2 = p1 + nz.p_short
    p = np.array([p1, p2, p2 + nz.p_invalid])
    u = short = _EMPTY
    if p[2] > 0.0:
        u = rng.random(n)
        short = rng.random(_rare_beams(r, u, p[2], r_max))
    res = np.empty(n, dtype=np.float32)
    _finish(r, out, u, short, p, float(spec.range_min_m), r_max, res)
    return res
