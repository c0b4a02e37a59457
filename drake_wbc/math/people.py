"""Tracking moving obstacle points (people) between LIDAR scans, so that
their speed can enter the separation kept from them
(drake_wbc.math.separation, eq. (protective)).

Once a scan (15 Hz, not every control tick), in the world frame of the
base's odometry, so that a static shape stays still while the base moves:

1. Clusters (`scan_clusters`): the scan's points in their order (beam by
   beam, scanner after scanner), split where two consecutive points are
   farther apart than `cluster_gap`. A cluster of MIN_CLUSTER_POINTS or
   more, no larger than `max_cluster_size` from its first point to its
   last (a person, a pillar, a crate; not a wall) and whose centroid is
   within `tracked_range` of the footprint is a candidate, represented
   by its centroid.
2. Association (`track_scan`): each live track's position is predicted
   over the time since the last scan; the pairs (track, candidate) are
   taken nearest first, each at most once, within `gate`. A candidate
   left over starts a track; a track not seen for two scan periods ends.
3. Filter: a track's velocity starts from the finite difference of its
   first two scans, then an alpha-beta filter (gains alpha, beta) follows
   it: exact for a constant velocity, and a short memory (a few scans).
4. Moving: a track whose filtered speed has been above `min_speed` for
   `moving_scans` scans in a row, also relative to the base (the speed of
   its velocity less that of a point carried by the base there,
   `carried_velocity`), and which is `min_travel` or more from where it
   started, is a moving person from then on until `moving_hold`
   s after the last such scan. The travel tells a walk from the apparent
   motion of a static shape's centroid as the base drives by and its
   visible sides change (a crate's centroid moves by less than its
   half-diagonal); the speed relative to the base, the piece of a wall
   or a table at the edge of a scanner's field of view, which the edge
   carries along with the base (as fast as the base turns times its
   range), which no travel would tell.

Only moving tracks are treated as people (eq. (protective)); a cluster
that does not move keeps the static rule of eq. (allowed): a standing
person is not told from a pillar. Float only: `people_scan` is the
reference, in plain numpy; its float kernel (drake_wbc.math.kernels),
`people_scan_float`, finds the clusters and the points inside the
footprint in one compiled pass over the scan (drake_wbc.math.compiled)
and shares the rest (the association and the filter, a few tracks).
The stage runs it once a scan, when the points change. The tracks'
state is a flat float array (`TRACK_FIELDS` per track, MAX_TRACKS of them,
then the time of the last scan), which the stage keeps as its discrete
state.
"""

import numpy as np

from drake_wbc.math.base_state import BASE_POSE, BASE_TWIST, BASE_YAW
from drake_wbc.math.compiled import compiled, float_array
from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.repulsion import footprint_gap
from drake_wbc.math.separation import PeopleSeparationParameters

MAX_TRACKS = 8
"""How many clusters are tracked at once (the nearest first)."""

TRACK_FIELDS = ("x", "y", "vx", "vy", "scans", "last_seen", "fast_scans",
                "last_moving", "x0", "y0")
"""A track's entries: its position and velocity in the world (m, m/s), the
scans it was seen in (0: a free slot), the time it was last seen (s), the
scans in a row with its speed above min_speed, the last time it was a
moving person (s; NEVER before), and where it started (m)."""

(_X, _Y, _VX, _VY, _SCANS, _SEEN, _FAST, _MOVING, _X0,
 _Y0) = range(len(TRACK_FIELDS))
_WIDTH = len(TRACK_FIELDS)

NEVER = -1e9
"""s: the time of something that has not happened."""

TRACKER_SIZE = MAX_TRACKS * _WIDTH + 1
"""The size of the tracker's flat state: the tracks, then the time of the
last scan."""

MIN_CLUSTER_POINTS = 3
"""A candidate has at least this many points (a person at the tracked
range, 6 m, gives 8 or more beams; a lone return is no person)."""

LOST_SCANS = 2.0
"""A track not seen for this many scan periods (and a control period)
ends."""


def initial_tracker():
    """The tracker's state with no track (and no scan yet)."""
    state = np.zeros(TRACKER_SIZE)
    state[-1] = NEVER
    return state


def tracks_of(state):
    """The (MAX_TRACKS, len(TRACK_FIELDS)) view of the tracks in a flat
    tracker state."""
    return np.asarray(state)[:-1].reshape(MAX_TRACKS, _WIDTH)


def to_world(points, pose):
    """(M, 2) points in T_b to the world, with the base's pose
    [x, y, yaw]."""
    c, s = np.cos(pose[BASE_YAW]), np.sin(pose[BASE_YAW])
    return points @ np.array([[c, s], [-s, c]]) + [pose[0], pose[1]]


def scan_clusters(points, gap, max_size):
    """The candidate clusters of a scan (step 1 of the module's notes).

    Args:
        points: (M, 2) float points, in scan order.
        gap: m, the largest step within a cluster.
        max_size: m, the largest size of a candidate: the distance from
            its first point to its last (a person's width as a scanner
            sees it; a wall's length).

    Returns:
        (starts, ends, centroids): the candidates' index ranges
        [start, end) into `points` and their centroids (K, 2).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    empty = np.zeros(0, dtype=int)
    if len(points) < MIN_CLUSTER_POINTS:
        return empty, empty, np.zeros((0, 2))
    step = np.diff(points, axis=0)
    step *= step
    breaks = ((step[:, 0] + step[:, 1]) > gap * gap).nonzero()[0] + 1
    starts = np.empty(len(breaks) + 1, dtype=int)
    starts[0] = 0
    starts[1:] = breaks
    ends = np.empty_like(starts)
    ends[:-1] = breaks
    ends[-1] = len(points)
    enough = (ends - starts >= MIN_CLUSTER_POINTS).nonzero()[0]
    if not len(enough):
        return empty, empty, np.zeros((0, 2))
    starts, ends = starts[enough], ends[enough]
    chord = points[ends - 1] - points[starts]
    small = (chord * chord).sum(axis=1) <= max_size * max_size
    starts, ends = starts[small], ends[small]
    # Sums by cumulative sums: one pass for every cluster.
    total = np.zeros((len(points) + 1, 2))
    np.cumsum(points, axis=0, out=total[1:])
    centroids = (total[ends] - total[starts]) / (ends - starts)[:, None]
    return starts, ends, centroids


def track_scan(state, centroids, time, params, base=(0.0,) * 6):
    """The tracker's state after a scan at `time` (steps 2 to 4).

    Args:
        state: the flat tracker state before it (`initial_tracker`).
        centroids: (K, 2) the candidates' centroids in the world.
        time: s, the scan's time.
        params: PeopleSeparationParameters.
        base: the base's state [x, y, yaw, vx, vy, wz] (the pose in the
            world, the twist in T_b), for the velocity of a point carried
            by the base (`carried_velocity`).

    Returns:
        (new state, match): match (K,) the track slot each candidate went
        to (-1 if none was free).
    """
    new = np.array(state, dtype=float)
    tracks = tracks_of(new)
    dt = time - new[-1]
    if dt < 0.0:
        # Time set back (a context whose time is set earlier): the tracks,
        # seen in its future, would neither follow a candidate nor end,
        # and would keep the slots from new ones; they start again.
        tracks[:] = 0.0
    new[-1] = time
    centroids = np.asarray(centroids, dtype=float).reshape(-1, 2)
    match = np.full(len(centroids), -1)
    # End the tracks not seen for too long.
    lost = time - tracks[:, _SEEN] > LOST_SCANS * params.scan_period + 0.011
    tracks[lost & (tracks[:, _SCANS] > 0)] = 0.0
    live = (tracks[:, _SCANS] > 0).nonzero()[0]
    if len(live) and len(centroids) and dt > 0.0:
        since = time - tracks[live, _SEEN]
        predicted = tracks[live, :2] + tracks[live, 2:4] * since[:, None]
        distance = np.hypot(
            predicted[:, None, 0] - centroids[None, :, 0],
            predicted[:, None, 1] - centroids[None, :, 1])
        order = np.argsort(distance, axis=None, kind="stable")
        used_track = np.zeros(len(live), dtype=bool)
        for flat in order.tolist():
            i, k = divmod(flat, len(centroids))
            if distance[i, k] > params.gate:
                break
            if used_track[i] or match[k] >= 0:
                continue
            used_track[i] = True
            match[k] = live[i]
            _update_track(tracks[live[i]], predicted[i], centroids[k],
                          since[i], time, params, base)
    # New tracks for the candidates left, nearest slots first free.
    free = (tracks[:, _SCANS] == 0).nonzero()[0].tolist()
    for k in (match < 0).nonzero()[0].tolist():
        if not free:
            break
        slot = free.pop(0)
        tracks[slot] = [centroids[k, 0], centroids[k, 1], 0.0, 0.0, 1.0,
                        time, 0.0, NEVER, centroids[k, 0], centroids[k, 1]]
        match[k] = slot
    return new, match


def carried_velocity(point, base):
    """The world velocity (2,) of a point fixed in T_b at the world point
    `point`, for the base's state [x, y, yaw, vx, vy, wz] (the twist in
    T_b): R(yaw) [vx, vy] + wz x (point - [x, y])."""
    x, y, yaw, vx, vy, wz = base
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([c * vx - s * vy - wz * (point[1] - y),
                     s * vx + c * vy + wz * (point[0] - x)])


def _update_track(track, predicted, measured, dt, time, params, base):
    """One track's filter step, in place (step 3 and 4)."""
    if track[_SCANS] == 1.0:
        # The finite difference of the first two scans.
        track[2:4] = (measured - track[:2]) / dt
        track[:2] = measured
    else:
        residual = measured - predicted
        track[:2] = predicted + params.alpha * residual
        track[2:4] += (params.beta / dt) * residual
    track[_SCANS] += 1.0
    track[_SEEN] = time
    carried = carried_velocity(track[:2], base)
    if (np.hypot(track[_VX], track[_VY]) > params.min_speed
            and np.hypot(track[_VX] - carried[0], track[_VY] - carried[1])
            > params.min_speed):
        track[_FAST] += 1.0
        if track[_FAST] >= params.moving_scans and np.hypot(
                track[_X] - track[_X0],
                track[_Y] - track[_Y0]) >= params.min_travel:
            track[_MOVING] = time
    else:
        track[_FAST] = 0.0


def moving_tracks(state, time, params):
    """The slots of the tracks that are moving people at `time`
    (seen at the last scan and moving within moving_hold; a track that
    never moved is not, whatever moving_hold)."""
    tracks = tracks_of(state)
    return ((tracks[:, _SCANS] > 0)
            & (tracks[:, _SEEN] >= state[-1])
            & (tracks[:, _MOVING] > NEVER)
            & (time - tracks[:, _MOVING] <= params.moving_hold + 1e-9)
            ).nonzero()[0]


def people_scan(state, points, base, time, half_sizes, params):
    """One scan's tracking from the points in T_b (the stage's call).

    Args:
        state: the flat tracker state.
        points: (M, 2) float points in T_b, in scan order.
        base: the base's state [x, y, yaw, vx, vy, wz] (odometry: the
            pose in its world, the twist in T_b).
        time: s.
        half_sizes: the footprint's half-sizes (a, b), m.
        params: PeopleSeparationParameters.

    Returns:
        (new state, people, inside): people a list of (slot, nearest
        point in T_b (2,), velocity in T_b (2,)) of the moving tracks seen
        in this scan, with the cluster's point nearest the footprint;
        inside whether a point is on or inside the footprint.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    a, b = half_sizes
    inside = bool(((np.abs(points[:, 0]) <= a)
                   & (np.abs(points[:, 1]) <= b)).any())
    starts, ends, centroids = scan_clusters(points, params.cluster_gap,
                                            params.max_cluster_size)
    return _tracked(state, points, base, time, half_sizes, params, inside,
                    starts, ends, centroids)


def _tracked(state, points, base, time, half_sizes, params, inside, starts,
             ends, centroids):
    """`people_scan` from the scan's clusters (`scan_clusters`) and
    whether a point is inside the footprint: the candidates within
    tracked_range, their tracking, the moving people."""
    if len(centroids):
        near = footprint_gap(centroids, half_sizes) <= params.tracked_range
        starts, ends, centroids = starts[near], ends[near], centroids[near]
    if not len(centroids) and not (tracks_of(state)[:, _SCANS] > 0).any():
        # Nothing to track (the usual scan of a static scene).
        new = np.array(state, dtype=float)
        new[-1] = time
        return new, [], inside
    base = np.asarray(base, dtype=float)
    pose = base[BASE_POSE]
    world = to_world(centroids, pose) if len(centroids) else centroids
    new, match = track_scan(state, world, time, params, base)
    people = []
    moving = set(moving_tracks(new, time, params).tolist())
    if moving:
        c, s = np.cos(pose[BASE_YAW]), np.sin(pose[BASE_YAW])
        tracks = tracks_of(new)
        for k in (match >= 0).nonzero()[0].tolist():
            slot = int(match[k])
            if slot not in moving:
                continue
            cluster = points[starts[k]:ends[k]]
            nearest = cluster[int(np.argmin(footprint_gap(cluster,
                                                          half_sizes)))]
            vx, vy = tracks[slot, _VX], tracks[slot, _VY]
            people.append((slot, nearest.copy(),
                           np.array([c * vx + s * vy, -s * vx + c * vy])))
    return new, people, inside


def _walkers_scan(rng, walkers, time, pose, half_sizes):
    """The points (T_b, scan order) of a scene at `time` seen from the
    base's `pose`: each walker (start (2,), velocity (2,), whether seen)
    a short arc of points, a wall, now and then a crate, a lone return
    or a point inside the footprint."""
    parts = []
    for start, velocity, seen in walkers:
        if seen:
            centre = start + velocity * time
            angle = np.linspace(-1.2, 1.2, int(rng.integers(3, 12)))
            parts.append(centre + 0.15 * np.column_stack(
                [np.cos(angle), np.sin(angle)]))
    if rng.random() < 0.7:
        x = np.arange(-3.0, 3.0, 0.03)
        parts.append(np.column_stack([x, np.full(len(x), 2.5)]))
    if rng.random() < 0.3:
        parts.append(np.array([1.5, -1.0]) + rng.uniform(0.0, 0.4, (6, 2)))
    if rng.random() < 0.2:
        parts.append(rng.uniform(-4.0, 4.0, (1, 2)))
    world = np.concatenate(parts) if parts else np.zeros((0, 2))
    c, s = np.cos(pose[BASE_YAW]), np.sin(pose[BASE_YAW])
    points = (world - pose[:2]) @ np.array([[c, -s], [s, c]])
    if rng.random() < 0.1:
        points = np.concatenate(
            [points, rng.uniform(-1.0, 1.0, (1, 2)) * half_sizes])
    return points


def _scan_inputs(rng):
    """The arguments of people_scan after a few scans (by the reference)
    of walkers who appear, walk, stop being seen and come back, with a
    wall, crates, lone returns and points inside the footprint, from a
    base that moves; now and then a scan after a long gap (every track
    lost) or fewer than MIN_CLUSTER_POINTS points."""
    params = PeopleSeparationParameters(
        min_travel=float(rng.choice([0.0, 0.5])),
        moving_scans=int(rng.choice([1, 3])))
    half_sizes = (float(rng.uniform(0.2, 0.5)), float(rng.uniform(0.2, 0.4)))
    walkers = [[rng.uniform(-4.0, 4.0, 2),
                rng.uniform(-1.6, 1.6, 2) * rng.choice([0.0, 1.0]), True]
               for _ in range(rng.integers(0, 4))]
    base = np.concatenate([rng.uniform(-1.0, 1.0, 3),
                           rng.uniform(-0.3, 0.3, 3)])
    state, time = initial_tracker(), 0.0
    for _ in range(rng.integers(0, 10)):
        time += params.scan_period * float(rng.choice([1.0, 1.0, 1.0, 4.0]))
        for walker in walkers:
            walker[2] = rng.random() < 0.85
        pose = base[BASE_POSE] + base[BASE_TWIST] * time
        state, _, _ = people_scan(state, _walkers_scan(
            rng, walkers, time, pose, half_sizes), base, time, half_sizes,
            params)
    time += params.scan_period
    pose = base[BASE_POSE] + base[BASE_TWIST] * time
    points = _walkers_scan(rng, walkers, time, pose, half_sizes)
    if rng.random() < 0.05:
        points = points[:int(rng.integers(0, MIN_CLUSTER_POINTS))]
    return state, points, base, time, half_sizes, params


@fast_kernel(people_scan, sample=_scan_inputs)
def people_scan_float(state, points, base, time, half_sizes, params):
    """`people_scan` with the scan's clusters and its points inside the
    footprint found in one compiled pass (`scan_clusters`'s steps, the
    same sums, so the same centroids)."""
    points = np.reshape(float_array(points), (-1, 2))
    a, b = half_sizes
    inside, starts, ends, centroids = _scan_loop(
        points, float(a), float(b), float(params.cluster_gap),
        float(params.max_cluster_size), MIN_CLUSTER_POINTS)
    return _tracked(state, points, base, time, half_sizes, params, inside,
                    starts, ends, centroids)


@compiled
def _scan_loop(points, a, b, gap, max_size, min_points):
    """(inside, starts, ends, centroids) of a scan: whether a point is on
    or inside the footprint, and `scan_clusters`."""
    count = points.shape[0]
    inside = False
    for i in range(count):
        if abs(points[i, 0]) <= a and abs(points[i, 1]) <= b:
            inside = True
            break
    starts = np.empty(count, np.int64)
    ends = np.empty(count, np.int64)
    centroids = np.empty((count, 2))
    found = 0
    if count < min_points:
        return inside, starts[:0], ends[:0], centroids[:0]
    # The cumulative sums of np.cumsum, from 0.
    total = np.zeros((count + 1, 2))
    for i in range(count):
        total[i + 1, 0] = total[i, 0] + points[i, 0]
        total[i + 1, 1] = total[i, 1] + points[i, 1]
    start = 0
    for i in range(1, count + 1):
        if i < count:
            dx = points[i, 0] - points[i - 1, 0]
            dy = points[i, 1] - points[i - 1, 1]
            if not dx * dx + dy * dy > gap * gap:
                continue
        # A cluster [start, i).
        if i - start >= min_points:
            cx = points[i - 1, 0] - points[start, 0]
            cy = points[i - 1, 1] - points[start, 1]
            if cx * cx + cy * cy <= max_size * max_size:
                size = i - start
                starts[found] = start
                ends[found] = i
                centroids[found, 0] = (total[i, 0] - total[start, 0]) / size
                centroids[found, 1] = (total[i, 1] - total[start, 1]) / size
                found += 1
        start = i
    return inside, starts[:found], ends[:found], centroids[:found]
