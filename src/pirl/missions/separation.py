"""A fleet's missions in time: every UAV's flight as positions against time, and the check that
every pair keeps its separation (``mission.separation_m``) at every sampled instant.

The time model is the sorties' own (:func:`pirl.missions.write.sorties`): a leg takes its
horizontal metres over ``speed_m_s`` plus its vertical metres over ``climb_m_s`` and is flown
in a straight line at a constant rate; a camera change or a photo holds the UAV still for
``photo_s``; take-off climbs straight up from the UAV's own home (its start cell) before its
first leg, and the return flies across at its altitude, then descends straight down at home.
The fleet flies in **waves**: sortie n of every UAV takes off together (batteries are
swapped between waves, so every UAV's sortie n starts at the same instant). A UAV on the
ground (before its take-off, after its landing) stands at its home; two UAVs both on the
ground are parked, not a conflict.

A pair keeps its separation when it is at least ``separation_m`` apart horizontally *or* in
altitude. Where it would not, the rule is a **delayed take-off**: UAVs are taken in order,
each held on the ground for the smallest multiple of ``check_every_s`` (up to
``max_delay_s``) that keeps it separated from every UAV before it at every sampled instant;
a UAV no delay can separate is refused in one line.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pirl.config.errors import ConfigError
from pirl.config.mission import MissionSettings


@dataclass
class Track:
    """One sortie's flight: key instants (s from its take-off) and positions (metres east,
    north and up of the grid's origin) between which it moves in straight lines."""

    times: np.ndarray
    xyz: np.ndarray

    @property
    def seconds(self) -> float:
        return float(self.times[-1])

    def at(self, t: np.ndarray) -> np.ndarray:
        """(len(t), 3) positions at times ``t`` (before take-off and after landing: where it
        stands then)."""
        return np.stack([np.interp(t, self.times, self.xyz[:, i]) for i in range(3)], axis=1)


def track(
    items: Sequence[tuple[str, tuple[int, int, int] | None]],
    home: tuple[int, int],
    cell_m: float,
    level_m: float,
    s: MissionSettings,
) -> Track:
    """The track of one sortie from its items ``(kind, cell)`` (take-off, waypoints, camera
    changes, captures, return; :class:`pirl.missions.write.Item`) flown from ``home``."""

    def metres(cell: tuple[int, int, int]) -> np.ndarray:
        up = 0.0 if cell[2] < 0 else (cell[2] + 1) * level_m
        return np.array([(cell[0] + 0.5) * cell_m, (cell[1] + 0.5) * cell_m, up])

    ground = (home[0], home[1], -1)
    where = metres(ground)
    times, points = [0.0], [where]
    t = 0.0

    def go(to: np.ndarray) -> None:
        nonlocal t, where
        h = float(np.hypot(*(to - where)[:2]))
        t += h / s.speed_m_s + abs(float(to[2] - where[2])) / s.climb_m_s
        where = to
        times.append(t)
        points.append(where)

    for kind, cell in items:
        if kind == "takeoff":  # straight up from home, then across
            to = metres(cell)  # type: ignore[arg-type]
            go(np.array([where[0], where[1], to[2]]))
            go(to)
        elif kind == "waypoint":
            go(metres(cell))  # type: ignore[arg-type]
        elif kind == "rtl":  # across at its altitude, then straight down at home
            home_xyz = metres(ground)
            go(np.array([home_xyz[0], home_xyz[1], where[2]]))
            go(home_xyz)
        elif kind in ("gimbal", "zoom", "capture"):
            t += s.photo_s
            times.append(t)
            points.append(where)
    return Track(np.array(times), np.array(points))


@dataclass
class Separation:
    """The outcome of the check: each UAV's take-off delay per wave (s), the closest approach
    (horizontal metres, at an instant when the pair was within ``separation_m`` in altitude;
    inf when never), the smallest 3-D distance, the instants sampled."""

    delays_s: list[list[float]]
    closest_horizontal_m: float
    closest_3d_m: float
    samples: int

    def to_dict(self) -> dict:
        def num(x: float) -> float | None:
            return None if not np.isfinite(x) else round(float(x), 2)

        return {
            "delays_s": self.delays_s,
            "closest_horizontal_m": num(self.closest_horizontal_m),
            "closest_3d_m": num(self.closest_3d_m),
            "samples": self.samples,
        }


def separate(tracks: Sequence[Sequence[Track]], s: MissionSettings) -> Separation:
    """Check (and fix by delayed take-offs) the separation of a fleet whose UAV ``u`` flies
    ``tracks[u][n]`` in wave ``n``; :class:`ConfigError` when a UAV cannot be separated."""
    waves = max(len(t) for t in tracks)
    dt = s.check_every_s
    delays = [[0.0] * waves for _ in tracks]
    closest_h, closest_3d, samples = np.inf, np.inf, 0
    for n in range(waves):
        flying = [(u, t[n]) for u, t in enumerate(tracks) if n < len(t)]
        standing = [(u, t[-1]) for u, t in enumerate(tracks) if n >= len(t)]
        length = max(tr.seconds for _, tr in flying) + s.max_delay_s
        clock = np.arange(0.0, length + dt, dt)
        placed: list[np.ndarray] = [tr.at(np.array([tr.seconds])).repeat(len(clock), 0)
                                    for _, tr in standing]  # fmt: skip
        for u, tr in flying:
            for delay in np.arange(0.0, s.max_delay_s + dt / 2, dt):
                here = tr.at(clock - delay)
                if all(_apart(here, other, s.separation_m) for other in placed):
                    break
            else:
                raise ConfigError(
                    f"mission.separation_m={s.separation_m:g}: UAV {u + 1} cannot keep its "
                    f"distance in sortie {n + 1} even with its take-off held back "
                    f"mission.max_delay_s={s.max_delay_s:g} s; lower separation_m, raise "
                    "max_delay_s, or fly fewer UAVs"
                )
            delays[u][n] = round(float(delay), 3)
            for other in placed:
                h, v = _gaps(here, other)
                near = (v < s.separation_m) & ((here[:, 2] > 0) | (other[:, 2] > 0))
                if near.any():
                    closest_h = min(closest_h, float(h[near].min()))
                closest_3d = min(closest_3d, float(np.hypot(h, v).min()))
            placed.append(here)
        samples += len(clock)
    return Separation(delays, closest_h, closest_3d, samples)


def _gaps(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.hypot(*(a - b)[:, :2].T), np.abs(a[:, 2] - b[:, 2])


def _apart(a: np.ndarray, b: np.ndarray, separation: float) -> bool:
    h, v = _gaps(a, b)
    # Two UAVs standing on the ground at their homes are parked, not flying near each other.
    parked = (a[:, 2] <= 0) & (b[:, 2] <= 0)
    return bool(((h >= separation) | (v >= separation) | parked).all())


__all__ = ["Separation", "Track", "separate", "track"]
