"""The live world: schedule state for the current run, pymunk space, people, geometry arrays.

``World(spec, seed)`` jumps between runs with :meth:`World.reset` (the schedule is evaluated
for that run, never simulated through the hours in between) and advances people and the clock
with :meth:`World.step`. Geometry arrays and pymunk shapes of objects are rebuilt only on
``reset``; a step only moves people. Time is kept as an integer count of microseconds since
the run started, so weeks of stepping do not drift.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pymunk
from numpy.typing import NDArray

from dynmap_sim.world.calendar import Calendar, RunSlot
from dynmap_sim.world.geometry import GeometryView, StaticGeometry, build_static
from dynmap_sim.world.people import Crowd, SocialForce
from dynmap_sim.world.people.legs import leg_centres_into
from dynmap_sim.world.people.params import LEG_RADIUS_M
from dynmap_sim.world.polygons import FloatArray, polygon_edges
from dynmap_sim.world.schedule import ObjectState, Schedule, Snapshot
from dynmap_sim.world.spec import WorldSpec

#: pymunk collision types of the world's shapes.
COLLISION_STATIC = 1
COLLISION_PERSON = 2
#: pymunk shape-filter category bits: walls and objects, people.
CATEGORY_STATIC = 0b01
CATEGORY_PERSON = 0b10
_PEOPLE_TAG = 0x9E0913
#: People's pymunk bodies are moved at every step only near the robot (:func:`_near_m`);
#: the others lazily: on the next access to ``World.space``, or when they come that near.
#: The robot's next collision query is a box of half-width its radius plus one step's travel
#: (at most ``SYNC_SPEED_MPS`` times the step) around it, and pymunk returns the shapes whose
#: bounding box (a person's: centre +- radius) meets it: so a body that query can return lies
#: within ``sqrt(2)`` times (robot radius + travel + the person's radius) of the robot,
#: plus ``SYNC_MARGIN_M`` for the query's skin and rounding.
SYNC_MARGIN_M = 0.01
SYNC_SPEED_MPS = 4.0


class World:
    """A world file brought to life for one ``seed`` (docs/architecture.md §2).

    * ``calendar`` (:class:`Calendar`: ``slots``, ``n_days``, ``runs_per_day``), ``slot``
      (the current :class:`RunSlot`), ``day``, ``run``;
    * ``reset(day, run)`` jumps to the start of a run; ``step(dt_s, robot_pose, robot_radius_m)``
      advances people and the clock; ``time_s`` (since midnight), ``elapsed_s`` (in the run);
    * ``geometry`` (:class:`GeometryView` for sensors), ``space`` (pymunk: walls and objects
      as static shapes, people as kinematic circles; the space is never stepped here;
      people's bodies are brought up to date on every access to ``space``, and at every
      step for those near the robot (``SYNC_MARGIN_M``), so a robot that holds the space and
      queries the box its next move can reach always sees people where they are; after
      moving the robot by hand, call ``sync_space()``),
      ``wall_segments()``, ``people_poses()``, ``people_radii()``, ``objects`` (current
      :class:`ObjectState` tuple), ``route_blocked()``;
    * ``snapshot(day, run)``: the state at the start of any run, a pure function of (file,
      seed, day, run) that leaves the live state alone.

    Randomness: shuffles draw from ``SeedSequence((seed, tag, event, day, run))`` and people
    from ``SeedSequence((seed, tag, day, run))``, so any run is reproducible on its own.
    """

    def __init__(self, spec: WorldSpec, seed: int = 0) -> None:
        if int(seed) < 0:
            raise ValueError(f"seed must be a non-negative integer, not {seed!r}")
        self.spec = spec
        self.seed = int(seed)
        self.calendar = Calendar(spec.calendar)
        self.schedule = Schedule(spec, self.calendar)
        self._space = pymunk.Space()
        self._space.gravity = (0.0, 0.0)
        self._static_filter = pymunk.ShapeFilter(categories=CATEGORY_STATIC)
        self._person_filter = pymunk.ShapeFilter(categories=CATEGORY_PERSON)
        for _, poly in self.schedule.walls:
            self._space.add(self._static_shape(poly, None))
        ws = [polygon_edges(poly) for _, poly in self.schedule.walls]
        self._wall_segments = np.concatenate(ws) if ws else np.zeros((0, 4))
        self._wall_segments.setflags(write=False)
        self._object_shapes: dict[str, tuple[Any, pymunk.Shape]] = {}
        self._people_bodies: list[pymunk.Body] = []
        self._snapshots: dict[tuple[int, int], Snapshot] = {}
        self._static_version = 0
        self.reset(1, 1)

    # -- pymunk helpers -------------------------------------------------------------------
    def _static_shape(self, poly: FloatArray, circle) -> pymunk.Shape:
        body = self._space.static_body
        if circle is not None:
            shape: pymunk.Shape = pymunk.Circle(body, circle[2], offset=(circle[0], circle[1]))
        else:
            shape = pymunk.Poly(body, [tuple(v) for v in poly.tolist()])
        shape.collision_type = COLLISION_STATIC
        shape.filter = self._static_filter
        shape.friction = 0.8
        return shape

    def _sync_objects(self, objects: tuple[ObjectState, ...]) -> None:
        """Replace pymunk shapes of objects whose state changed (static index refreshed)."""
        wanted = {o.id: o for o in objects if o.kind != "wall" or o.id in self.schedule.objects}
        changed = False
        for oid in list(self._object_shapes):
            key, shape = self._object_shapes[oid]
            o = wanted.get(oid)
            if o is None or key != (o.pose, o.polygon.tobytes()):
                self._space.remove(shape)
                del self._object_shapes[oid]
                changed = True
        for oid, o in wanted.items():
            if oid not in self._object_shapes:
                shape = self._static_shape(o.polygon, o.circle)
                self._space.add(shape)
                self._object_shapes[oid] = ((o.pose, o.polygon.tobytes()), shape)
                changed = True
        if changed:
            self._space.reindex_static()

    # -- public API -----------------------------------------------------------------------
    def reset(self, day: int, run: int) -> None:
        """Jump the live state to the start of run ``(day, run)`` (1-based)."""
        t = self.calendar.slot_index(day, run)
        self.day, self.run = day, run
        self.slot: RunSlot = self.calendar.slots[t]
        objects = self.schedule.object_states(self.seed, t)
        signature = tuple((o.id, o.polygon.tobytes()) for o in objects)
        if signature != getattr(self, "_signature", None):  # rebuild only what changed
            self._sync_objects(objects)
            self._static: StaticGeometry = build_static(objects)
            self._static_version += 1
            self._signature = signature
        self.objects = objects
        self._time_us = 0
        # people
        self._forces, self._crowd = self._spawn(day, run, objects)
        for b in self._people_bodies:
            self._space.remove(b, *b.shapes)
        self._people_bodies = []
        for i in range(self._crowd.n):
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            body.position = tuple(self._crowd.pos[i])
            shape = pymunk.Circle(body, float(self._crowd.radius[i]))
            shape.collision_type = COLLISION_PERSON
            shape.filter = self._person_filter
            self._space.add(body, shape)
            self._people_bodies.append(body)
        self._synced = self._crowd.pos.copy().view(np.complex128)[:, 0]  # bodies' positions
        self._stale = False  # some people's bodies lag behind the crowd
        # the largest body radius of the run's people [m] (how near the robot bodies sync)
        self._person_r_max = self._largest_person_radius()
        n_obj = len(self._static.object_ids)
        self._people_ids = self._crowd.ids
        nl = 2 * self._crowd.n
        self._circle_object = np.concatenate(
            [self._static.circle_object, n_obj + np.repeat(np.arange(self._crowd.n), 2)]
        ).astype(np.int32)
        self._circle_class = np.concatenate(
            [self._static.circle_class, np.full(nl, 5, dtype=np.int8)]
        ).astype(np.int8)
        self._object_ids = self._static.object_ids + self._people_ids
        self._circles_template = self._circles_start()
        self._refresh_people()

    def _circles_start(self) -> FloatArray:
        """The circles of a step before the legs' centres are written: the static ones,
        then one row per leg with its radius."""
        ns = self._static.circles.shape[0]
        out = np.empty((ns + 2 * self._crowd.n, 3))
        out[:ns] = self._static.circles
        out[ns:, 2] = LEG_RADIUS_M
        return out

    def _largest_person_radius(self) -> float:
        """The largest body radius [m] of the run's people (0 without people)."""
        return float(self._crowd.radius.max()) if self._crowd.n else 0.0

    def _spawn(self, day: int, run: int, objects: tuple[ObjectState, ...]):
        edges = [polygon_edges(o.polygon) for o in objects]  # circles as their 16-gons
        segments = np.concatenate(edges) if edges else np.zeros((0, 4))
        starts = np.cumsum([0] + [len(e) for e in edges[:-1]]).astype(np.int64)
        rng = np.random.default_rng(np.random.SeedSequence((self.seed, _PEOPLE_TAG, day, run)))
        forces = SocialForce(self.spec.people, segments, rng, outline_starts=starts)
        active = []
        for p in self.spec.people:
            d0 = 1 if p.start is None else self.calendar.day_of(p.start) or 1
            d1 = self.calendar.n_days if p.end is None else self.calendar.day_of(p.end) or 0
            active.append(d0 <= day <= d1)
        start = np.array(self.spec.robot.start[:2])
        slot = self.calendar.slot(day, run)
        crowd = forces.spawn(slot.start_s, active, keep_away=start, weekday=slot.date.weekday())
        return forces, crowd

    def _refresh_people(self) -> None:
        """The geometry with the people's legs where they are now."""
        if self._crowd.n:
            circles = self._circles_template.copy()
            ns = self._static.circles.shape[0]
            out = circles[ns:, :2].view(np.complex128)[:, 0]
            leg_centres_into(self._crowd, out)
        else:
            circles = self._static.circles
        self._set_circles(circles)

    def _set_circles(self, circles: FloatArray) -> None:
        """The geometry with ``circles`` ``(M, 3)``: the static ones, then the legs (as
        :meth:`_circles_start` lays them out, their centres placed)."""
        self._geometry = GeometryView(
            segments=self._static.segments,
            segment_object=self._static.segment_object,
            segment_class=self._static.segment_class,
            circles=circles,
            circle_object=self._circle_object,
            circle_class=self._circle_class,
            object_ids=self._object_ids,
            static_version=self._static_version,
        )

    def step(
        self,
        dt_s: float,
        robot_pose: tuple[float, float, float] | FloatArray | None = None,
        robot_radius_m: float = 0.2,
    ) -> None:
        """Advance the clock and people by ``dt_s`` seconds; people avoid the robot's disc."""
        self._tick(dt_s)
        if self._crowd.n == 0:
            return
        if robot_pose is None:
            self._forces.step(self._crowd, dt_s, None, robot_radius_m)
            self._sync_bodies(None)
        else:
            rxy = _robot_xy(robot_pose)
            self._forces.step(self._crowd, dt_s, rxy, robot_radius_m)
            self._sync_near(dt_s, rxy, robot_radius_m)
        self._refresh_people()

    def _tick(self, dt_s: float) -> None:
        """Advance the clock by ``dt_s`` seconds (checked)."""
        if not (math.isfinite(dt_s) and 0.0 <= dt_s <= 10.0):
            raise ValueError(f"dt_s must be a finite time step in [0, 10] s, not {dt_s!r}")
        self._time_us += int(round(dt_s * 1e6))

    def _sync_near(self, dt_s: float, rxy: FloatArray, robot_radius_m: float) -> None:
        """After the people moved: bring the bodies near the robot at ``rxy`` up to date."""
        near_m = _near_m(dt_s, robot_radius_m, self._person_r_max)
        self._sync_bodies(complex(rxy[0], rxy[1]), near_m)

    def _sync_bodies(self, robot_xy: complex | None, near_m: float = 0.0) -> None:
        """Move people's pymunk bodies to the crowd's state: all of them, or (with a robot)
        those whose new or last synced position lies within ``near_m`` of it."""
        crowd = self._crowd
        z = crowd.pos.view(np.complex128)[:, 0]
        synced = self._synced
        if robot_xy is None:
            idx: Any = slice(None)
            self._stale = False
        else:
            idx = _near(z, synced, robot_xy, near_m).nonzero()[0]
            self._stale = True  # (cheaper than checking whether all were near)
            if not len(idx):
                return
        self._move_bodies(idx)

    def _move_bodies(self, idx: Any) -> None:
        """Move the pymunk bodies of the people ``idx`` (indices, or ``slice(None)``: all)
        to the crowd's state."""
        crowd = self._crowd
        z = crowd.pos.view(np.complex128)[:, 0]
        bodies = self._people_bodies
        which = range(crowd.n) if isinstance(idx, slice) else idx.tolist()
        # the setters of the bodies' properties, without pymunk's per-attribute wrapper
        set_pos = pymunk.Body.position.fset
        set_vel = pymunk.Body.velocity.fset
        reindex = self._space.reindex_shapes_for_body
        for i, xy, uv in zip(which, crowd.pos[idx].tolist(), crowd.vel[idx].tolist(), strict=True):
            body = bodies[i]
            set_pos(body, xy)
            set_vel(body, uv)
            # the space is never stepped: refresh the shapes' cached positions for queries
            reindex(body)
        self._synced[idx] = z[idx]

    @property
    def space(self) -> pymunk.Space:
        """The pymunk space (walls and objects static, people kinematic), up to date."""
        return self.sync_space()

    def sync_space(self) -> pymunk.Space:
        """Bring every person's pymunk body up to date (after a teleport, say) and return
        the space."""
        if self._stale:
            self._sync_bodies(None)
        return self._space

    @property
    def time_s(self) -> float:
        """Clock time now, seconds since midnight."""
        return self.slot.start_s + self._time_us * 1e-6

    @property
    def elapsed_s(self) -> float:
        """Seconds since the current run started."""
        return self._time_us * 1e-6

    @property
    def geometry(self) -> GeometryView:
        """Geometry arrays for sensors (people's legs refreshed every step)."""
        return self._geometry

    def wall_segments(self) -> FloatArray:
        """Outline segments ``(N, 4)`` of the static walls only (the 'walls' prior)."""
        return self._wall_segments

    def people_poses(self) -> FloatArray:
        """People poses ``(P, 3)`` [m, rad] now."""
        return SocialForce.poses(self._crowd)

    def people_radii(self) -> FloatArray:
        """People body radii ``(P,)`` [m]."""
        return self._crowd.radius.copy()

    def route_blocked(self) -> bool:
        """True if the schedule blocks the route on purpose in the current run."""
        return any(o.blocks_route for o in self.objects)

    @property
    def crowd(self) -> Crowd:
        """Live people state (read-only by convention)."""
        return self._crowd

    def snapshot(self, day: int, run: int) -> Snapshot:
        """State at the start of run ``(day, run)``: a pure function of (file, seed, day, run).

        Does not touch the live state. ``people`` are the people's poses at the run start.
        """
        key = (day, run)
        snap = self._snapshots.get(key)
        if snap is None:
            t = self.calendar.slot_index(day, run)
            objects = self.schedule.object_states(self.seed, t)
            _, crowd = self._spawn(day, run, objects)
            people = SocialForce.poses(crowd)
            people.setflags(write=False)
            snap = Snapshot(day=day, run=run, objects=objects, people=people)
            self._snapshots[key] = snap
        return snap


def _near_m(dt_s: float, robot_radius_m: float, person_radius_m: float) -> float:
    """How near the robot a person's body is kept up to date [m]: any body the robot's next
    collision query can return (``SYNC_MARGIN_M``), for people of radius at most
    ``person_radius_m``."""
    reach = robot_radius_m + SYNC_SPEED_MPS * dt_s + person_radius_m
    return math.sqrt(2.0) * reach + SYNC_MARGIN_M


def _near(z: Any, synced: Any, robot_xy: Any, near_m: Any) -> NDArray[np.bool_]:
    """Which people's bodies to move (``World._sync_bodies``): those whose new position
    ``z`` or last synced position ``synced`` (``x + iy``) lies within ``near_m`` of the robot
    at ``robot_xy`` (scalars, or one value per person)."""
    return (np.abs(z - robot_xy) < near_m) | (np.abs(synced - robot_xy) < near_m)


def _robot_xy(robot_pose: tuple[float, float, float] | FloatArray) -> FloatArray:
    """The robot's position ``(2,)`` from its pose."""
    return np.array((float(robot_pose[0]), float(robot_pose[1])))
