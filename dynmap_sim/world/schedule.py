"""The schedule: what stands where at the start of any run (docs/architecture.md §2).

The state at slot ``t`` is a pure function of (world file, seed, t): start from the objects'
initial state, collect every event *occurrence* at or before ``t`` (a ``present`` window
contributes its start and its end, a recurring ``shuffle`` only its latest occurrence, a
``grow`` its interpolated scale), and apply them in (slot, file order), shuffles last within
a slot so that they place their group around whatever else changed in that run. Randomness of a
shuffle occurrence comes from ``numpy.random.SeedSequence((seed, event index, day, run))``,
never from a generator stepped through time, so runs can be visited in any order.

A ``periodic`` event is no occurrence: it is a mask applied last, on the state at ``t``, from
the run's date and clock time (whether its window applies that day is drawn from
``SeedSequence((seed, tag, event index, date ordinal))``); it makes its target absent (or a
door closed) where its rule says so and leaves every other state as the schedule made it.
A shuffle places its group around the others as they are in its run, periodic rules included.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from dynmap_sim.world.calendar import Calendar
from dynmap_sim.world.polygons import (
    FloatArray,
    ccw,
    edge_normals,
    sat_separation,
    thick_segment,
    transform,
)
from dynmap_sim.world.spec import (
    WEEKDAYS,
    AddEvent,
    DoorEvent,
    GrowEvent,
    InstallEvent,
    MoveEvent,
    ObjectSpec,
    PeriodicEvent,
    PresentEvent,
    RemoveEvent,
    ShuffleEvent,
    WorldSpec,
)

_SHUFFLE_TRIES = 200
_SHUFFLE_TAG = 0x5F1E
_PERIODIC_TAG = 0x9E71


@dataclass(frozen=True)
class ObjectState:
    """One object at one moment: ``polygon`` is its outline ``(K, 2)`` in the map frame [m].

    ``circle`` is ``(x_m, y_m, r_m)`` for round objects (their polygon is a circumscribed
    16-gon). ``blocks_route`` marks an object the schedule put on the route on purpose.
    """

    id: str
    kind: str
    group: str | None
    polygon: FloatArray
    circle: tuple[float, float, float] | None = None
    blocks_route: bool = False
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Snapshot:
    """State at the start of run ``(day, run)``: static walls and present objects, people."""

    day: int
    run: int
    objects: tuple[ObjectState, ...]
    people: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))

    def by_id(self) -> dict[str, ObjectState]:
        """Objects keyed by id."""
        return {o.id: o for o in self.objects}


@dataclass
class _State:
    present: bool
    pose: tuple[float, float, float]
    scale: float = 1.0
    open: bool = False
    blocks_route: bool = False


def _area(poly: FloatArray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)))


def wall_pieces(spec: WorldSpec) -> list[tuple[str, FloatArray]]:
    """Each wall polyline segment as a capped rectangle ``(id, polygon)``.

    A single-segment wall keeps its id; pieces of a polyline are ``<id>.<k>``.
    """
    out = []
    for w in spec.walls:
        n = len(w.points) - 1
        for k in range(n):
            pid = w.id if n == 1 else f"{w.id}.{k}"
            out.append((pid, ccw(thick_segment(w.points[k], w.points[k + 1], w.thickness_m))))
    return out


class Schedule:
    """Compiled schedule of a world: events resolved to slot indices, groups expanded."""

    def __init__(self, spec: WorldSpec, calendar: Calendar) -> None:
        self.spec = spec
        self.calendar = calendar
        self.objects: dict[str, ObjectSpec] = {o.id: o for o in spec.objects}
        self.local: dict[str, FloatArray] = {o.id: o.local_vertices() for o in spec.objects}
        self._areas = {oid: _area(p) for oid, p in self.local.items()}
        self.groups: dict[str, list[str]] = {}
        for o in spec.objects:
            if o.group is not None:
                self.groups.setdefault(o.group, []).append(o.id)
        self.walls = wall_pieces(spec)
        self._windowed: set[str] = set()
        for ev in spec.schedule:
            if isinstance(ev, PresentEvent):
                self._windowed.update(self.groups.get(ev.group, []))
        self._periodic = [
            (i, ev) for i, ev in enumerate(spec.schedule) if isinstance(ev, PeriodicEvent)
        ]

    # -- time helpers -------------------------------------------------------------------
    def _slot(self, when, run: int = 1) -> int:
        day = self.calendar.day_of(when)
        if day is None:
            raise ValueError(f"{when} is outside the calendar")
        return self.calendar.slot_index(day, min(run, self.calendar.runs_per_day))

    def _end_slot(self, when) -> int:
        return self._slot(when, self.calendar.runs_per_day)

    def members(self, ev) -> list[str]:
        """Object ids an event applies to."""
        target = getattr(ev, "target", None)
        if target is not None:
            return [target]
        return list(self.groups.get(ev.group, []))

    # -- evaluation -----------------------------------------------------------------------
    def occurrences(self, t: int) -> list[tuple[int, int, str, object]]:
        """Event occurrences at or before slot ``t`` as ``(slot, order, what, payload)``."""
        occ: list[tuple[int, int, str, object]] = []
        last = self.calendar.n_slots - 1
        for i, ev in enumerate(self.spec.schedule):
            if isinstance(ev, PresentEvent):
                s0, s1 = self._slot(ev.start), self._end_slot(ev.end)
                if s0 <= t:
                    occ.append((s0, i, "present", ev))
                if s1 + 1 <= t:
                    occ.append((s1 + 1, i, "absent", ev))
            elif isinstance(ev, ShuffleEvent):
                s0 = self._slot(ev.start)
                s1 = last if ev.end is None else self._end_slot(ev.end)
                if s0 <= t:
                    s = s0 + ((min(t, s1) - s0) // ev.every_runs) * ev.every_runs
                    occ.append((s, i, "shuffle", ev))
            elif isinstance(ev, PeriodicEvent):
                continue  # a mask on the state at t, not an occurrence (see states)
            elif isinstance(ev, GrowEvent):
                s0, s1 = self._slot(ev.start), self._end_slot(ev.end)
                if s0 <= t:
                    frac = 1.0 if s1 <= s0 else min(1.0, (t - s0) / (s1 - s0))
                    occ.append(
                        (s0, i, "grow", ev.scale_start + frac * (ev.scale_end - ev.scale_start))
                    )
            else:
                s = self._slot(ev.at, ev.run)
                if s <= t:
                    occ.append((s, i, ev.action, ev))
        # within one run, scheduled changes come first and shuffles then place around them
        occ.sort(key=lambda o: (o[0], o[2] == "shuffle", o[1]))
        return occ

    def states(self, seed: int, t: int) -> dict[str, _State]:
        """Per-object state at the start of slot ``t`` (pure in ``seed`` and ``t``)."""
        st = {
            oid: _State(present=o.present and oid not in self._windowed, pose=o.pose, open=o.open)
            for oid, o in self.objects.items()
        }
        for slot, i, what, payload in self.occurrences(t):
            ev = self.spec.schedule[i]
            if what in ("add", "install"):
                assert isinstance(ev, AddEvent | InstallEvent)
                for oid in self.members(ev):
                    st[oid].present = True
                    st[oid].blocks_route = ev.blocks_route
            elif what == "remove":
                assert isinstance(ev, RemoveEvent)
                for oid in self.members(ev):
                    st[oid].present = False
            elif what == "move":
                assert isinstance(ev, MoveEvent)
                st[ev.target].pose = ev.pose
                st[ev.target].blocks_route = ev.blocks_route
            elif what in ("open", "close"):
                assert isinstance(ev, DoorEvent)
                st[ev.target].open = what == "open"
            elif what in ("present", "absent"):
                assert isinstance(ev, PresentEvent)
                for oid in self.members(ev):
                    st[oid].present = what == "present"
            elif what == "grow":
                assert isinstance(ev, GrowEvent) and isinstance(payload, float)
                st[ev.target].scale = payload
            elif what == "shuffle":
                assert isinstance(ev, ShuffleEvent)
                self._shuffle(st, ev, i, seed, slot)
        for i, ev in self._periodic:
            self._apply_periodic(st, ev, i, seed, t)
        return st

    def periodic_state(self, ev: PeriodicEvent, idx: int, seed: int, t: int) -> str | None:
        """The state periodic event ``ev`` (schedule index ``idx``) gives its target at slot
        ``t``: its ``state`` at a run inside a window that applies that day, the opposite at
        the other runs of its days, ``None`` on a day outside ``start`` .. ``end``."""
        rs = self.calendar.slots[t]
        first = self.calendar.day_of(ev.start)
        last = self.calendar.n_days if ev.end is None else self.calendar.day_of(ev.end)
        if first is None or last is None or not first <= rs.day <= last:
            return None
        other = {"present": "absent", "absent": "present", "open": "closed", "closed": "open"}
        days = WEEKDAYS if ev.weekdays is None else ev.weekdays
        if WEEKDAYS[rs.date.weekday()] not in days or ev.p <= 0.0:
            return other[ev.state]
        if ev.p < 1.0:
            ss = np.random.SeedSequence((int(seed), _PERIODIC_TAG, idx, rs.date.toordinal()))
            if not np.random.default_rng(ss).random() < ev.p:
                return other[ev.state]
        inside = ev.from_minutes * 60.0 <= rs.start_s < ev.to_minutes * 60.0
        return ev.state if inside else other[ev.state]

    def _periodic_view(self, st: dict[str, _State], seed: int, t: int) -> dict[str, _State]:
        """``st`` with the periodic rules of slot ``t`` applied to copies (``st`` as it is
        without periodic events): what a shuffle at ``t`` places its group around."""
        if not self._periodic:
            return st
        view = {oid: replace(s) for oid, s in st.items()}
        for i, ev in self._periodic:
            self._apply_periodic(view, ev, i, seed, t)
        return view

    def _apply_periodic(
        self, st: dict[str, _State], ev: PeriodicEvent, idx: int, seed: int, t: int
    ) -> None:
        """Make the members of ``ev`` absent (or closed) where its rule says so at slot ``t``."""
        state = self.periodic_state(ev, idx, seed, t)
        for oid in self.members(ev) if state in ("absent", "closed") else ():
            if state == "absent":
                st[oid].present = False
            else:
                st[oid].open = False

    def polygon(self, oid: str, s: _State) -> FloatArray | None:
        """Outline of object ``oid`` in state ``s``, or ``None`` when it is absent."""
        o = self.objects[oid]
        if not s.present:
            return None
        pose = s.pose
        if o.kind == "door" and s.open:
            if o.open_pose is None:
                return None
            pose = o.open_pose
        return transform(self.local[oid], pose, s.scale)

    def _shuffle(self, st: dict[str, _State], ev: ShuffleEvent, idx: int, seed: int, slot: int):
        """Seeded re-placement of a group inside ``ev.region`` without overlaps.

        Members are placed largest first (ties in file order) by rejection sampling (uniform
        position and, with ``rotate``, heading) keeping ``min_gap_m`` from walls, other objects
        and members placed before; a member that finds no free spot is carried away (absent)
        until re-added.
        """
        rs = self.calendar.slots[slot]
        rng = np.random.default_rng(
            np.random.SeedSequence((int(seed), _SHUFFLE_TAG, idx, rs.day, rs.run))
        )
        x0, y0, x1, y1 = ev.region
        members = self.members(ev)
        mset = set(members)
        members.sort(key=lambda oid: -self._areas[oid])  # largest first packs best
        others = [p for _, p in self.walls]
        around = self._periodic_view(st, seed, slot)  # the others as they are in this run
        for oid, s in around.items():
            if oid in mset:
                continue
            p = self.polygon(oid, s)
            if p is not None:
                pmin, pmax = p.min(axis=0), p.max(axis=0)
                if pmax[0] > x0 - 1 and pmin[0] < x1 + 1 and pmax[1] > y0 - 1 and pmin[1] < y1 + 1:
                    others.append(p)
        boxes = [np.concatenate([q.min(axis=0), q.max(axis=0)]) for q in others]
        normals = [edge_normals(q) for q in others]
        gap = ev.min_gap_m
        for oid in members:
            s = st[oid]
            local = self.local[oid] * s.scale
            best = None
            for _ in range(_SHUFFLE_TRIES):
                th = float(rng.uniform(-np.pi, np.pi)) if ev.rotate else s.pose[2]
                rot = transform(local, (0.0, 0.0, th))
                rot_axes = edge_normals(rot)
                lo, hi = rot.min(axis=0), rot.max(axis=0)
                if hi[0] - lo[0] > x1 - x0 or hi[1] - lo[1] > y1 - y0:
                    continue  # this heading does not fit: draw another
                x = float(rng.uniform(x0 - lo[0], x1 - hi[0]))
                y = float(rng.uniform(y0 - lo[1], y1 - hi[1]))
                poly = rot + np.array([x, y])
                box = np.array([lo[0] + x, lo[1] + y, hi[0] + x, hi[1] + y])
                ok = True
                if boxes:  # broad phase on bounding boxes, SAT only for near ones
                    bb = np.array(boxes)
                    near = np.flatnonzero(
                        (bb[:, 0] < box[2] + gap)
                        & (bb[:, 2] > box[0] - gap)
                        & (bb[:, 1] < box[3] + gap)
                        & (bb[:, 3] > box[1] - gap)
                    )
                    ok = all(
                        sat_separation(poly, others[k], rot_axes, normals[k]) >= gap for k in near
                    )
                if ok:
                    best = (x, y, th), poly, box, rot_axes
                    break
            if best is None:  # no free spot found: it is carried away for now
                s.present = False
                continue
            s.pose = best[0]
            others.append(best[1])
            boxes.append(best[2])
            normals.append(best[3])

    def object_states(self, seed: int, t: int) -> tuple[ObjectState, ...]:
        """Walls (static pieces) and present objects at slot ``t`` as :class:`ObjectState`."""
        out = [ObjectState(id=pid, kind="wall", group=None, polygon=p) for pid, p in self.walls]
        for oid, s in self.states(seed, t).items():
            p = self.polygon(oid, s)
            if p is None:
                continue
            o = self.objects[oid]
            circle = None
            if o.shape == "circle":
                assert o.radius_m is not None
                circle = (float(s.pose[0]), float(s.pose[1]), o.radius_m * s.scale)
            p.setflags(write=False)
            out.append(
                ObjectState(
                    id=oid,
                    kind=o.kind,
                    group=o.group,
                    polygon=p,
                    circle=circle,
                    blocks_route=s.blocks_route,
                    pose=tuple(float(v) for v in s.pose),  # type: ignore[arg-type]
                )
            )
        return tuple(out)
