"""The demonstrator (:class:`Expert`): from the ground-truth boundaries of one window, the next
vertex and stop flag for any tracer state, and the border crossings training starts from."""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString

from csboundary.graph.polyline import segment_feet
from csboundary.labels.boundaries import Boundary
from csboundary.models.baselines.icurb.geometry import inside


class Expert:
    """The demonstrator of one window: ground-truth boundaries in window pixels, ``size`` (w, h)."""

    def __init__(self, boundaries: list[Boundary], size: tuple[int, int], step_px: float):
        self.tracks, self.box, self.step = boundaries, (0, 0, *size), float(step_px)
        self.cums = [b.cumulative for b in boundaries]
        self.a = np.concatenate([b.points[:-1] for b in boundaries] or [np.zeros((0, 2))])  # all segments a -> b
        self.b = np.concatenate([b.points[1:] for b in boundaries] or [np.zeros((0, 2))])
        self.track = np.concatenate(
            [np.full(len(b.points) - 1, k) for k, b in enumerate(boundaries)] or [np.zeros(0, int)]
        )
        self.s0 = np.concatenate([c[:-1] for c in self.cums] or [np.zeros(0)])  # arc length at a

    def at(self, k: int, s) -> np.ndarray:
        cum, pts = self.cums[k], self.tracks[k].points
        s = np.mod(s, cum[-1]) if self.tracks[k].closed else np.clip(s, 0, cum[-1])
        return np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=-1)

    def nearest(self, pos: np.ndarray) -> tuple[int, float, float, np.ndarray]:
        """Track, arc length and distance of the nearest ground-truth point, and its segment's direction."""
        t, _, d = segment_feet(self.a, self.b, np.asarray(pos, float))
        j = int(np.argmin(d))
        return (
            int(self.track[j]),
            float(self.s0[j] + t[j] * np.linalg.norm(self.b[j] - self.a[j])),
            float(d[j]),
            self.b[j] - self.a[j],
        )

    def act(
        self, pos: np.ndarray, direction: np.ndarray, start: tuple[int, float] | None = None
    ) -> tuple[np.ndarray, bool]:
        """The next vertex and the stop flag for a tracer at ``pos`` heading along ``direction``
        (``start``: the episode's (track, arc length), for closing rings)."""
        k, s, _, seg = self.nearest(pos)
        sign = 1.0 if np.dot(seg, direction) >= 0 else -1.0
        length, ahead, stop = self.cums[k][-1], self.step, False
        if not self.tracks[k].closed:
            room = length - s if sign > 0 else s
            if room <= ahead:
                ahead, stop = room, True
        elif start is not None and start[0] == k:
            back = ((start[1] - s) * sign) % length  # arc length ahead to the start
            if 0 < back <= ahead and length - back > self.step / 2:
                ahead, stop = back, True
        ss = s + sign * np.linspace(0, ahead, max(2, int(np.ceil(ahead / 0.5)) + 1))
        out = ~inside(self.at(k, ss), self.box)
        if not out.any():
            return self.at(k, ss[-1]), stop
        j = int(np.argmax(out))
        if j == 0:
            return np.clip(self.at(k, ss[0]), self.box[:2], self.box[2:]), True
        lo, hi = ss[j - 1], ss[j]
        for _ in range(30):  # bisect the border crossing
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if inside(self.at(k, mid), self.box)[0] else (lo, mid)
        return self.at(k, lo), True

    def starts(self) -> list[tuple[np.ndarray, np.ndarray, tuple[int, float]]]:
        """Every crossing of a boundary with the window border, heading inwards: (point, unit
        direction, (track, arc length))."""
        ring, out = shapely.box(*self.box).exterior, []
        for k, track in enumerate(self.tracks):
            line = LineString(track.points)
            for hit in shapely.get_parts(line.intersection(ring)):
                if hit.geom_type != "Point":
                    continue  # a piece running along the border
                s = line.project(hit)
                for sign in (1.0, -1.0):
                    ahead = self.at(k, s + sign)
                    if inside(ahead, self.box, eps=-1e-3)[0]:
                        point = self.at(k, s)
                        out.append((point, (ahead - point) / max(np.linalg.norm(ahead - point), 1e-9), (k, s)))
                        break
        return out

    def teacher(self, starts):
        """``act`` as the roll-out's teacher: the travel direction is the last step taken (the
        start's own direction before the first step)."""

        def action(i: int, history: np.ndarray) -> tuple[np.ndarray, bool]:
            d = history[-1] - history[-2]
            return self.act(history[-1], d if np.linalg.norm(d) > 1e-6 else starts[i][1], starts[i][2])

        return action
