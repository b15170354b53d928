"""Demonstration placements of ``lerobot-rnd-record`` (``--placements random|fps|fps-centre``): furthest point
sampling and the deterministic, indexable placement sequence of one env. ``lerobot_rnd.sim.record`` re-exports
these names."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def furthest_point_order(
    points: np.ndarray,
    n: int,
    low: np.ndarray,
    high: np.ndarray,
    start: np.ndarray | None = None,
    periods: np.ndarray | None = None,
) -> np.ndarray:
    """Indices of ``n`` points chosen greedily furthest from those chosen so far (coordinates scaled
    to the placement range; the first is the point nearest ``start``, by default the pool's mean).

    ``periods`` (one per coordinate, 0 = none): a coordinate whose values ``period`` apart show the same scene (a
    cube's yaw repeats every 90 degrees) is compared modulo its period, so the two ends of a cube's
    [-45, 45]-degree yaw range count as one pose, not the furthest apart."""
    span = np.where(high - low > 0, high - low, 1.0)
    x = (points - low) / span
    wrap = np.zeros(x.shape[1]) if periods is None else np.asarray(periods, dtype=np.float64) / span
    periodic = wrap > 0

    def dist(to: np.ndarray) -> np.ndarray:
        diff = np.abs(x - to)
        m = np.mod(diff[:, periodic], wrap[periodic])
        diff[:, periodic] = np.minimum(m, wrap[periodic] - m)
        return np.linalg.norm(diff, axis=1)

    centre = x.mean(0) if start is None else (np.asarray(start, dtype=np.float64) - low) / span
    first = int(np.argmin(dist(centre)))
    order = [first]
    d = dist(x[first])
    d[first] = -np.inf  # never chosen twice, even where the pool repeats a pose
    for _ in range(min(n, len(x)) - 1):
        nxt = int(np.argmax(d))
        order.append(nxt)
        d = np.minimum(d, dist(x[nxt]))
        d[nxt] = -np.inf
    return np.asarray(order, dtype=np.int64)


def placement_periods(env) -> np.ndarray:
    """Per placement coordinate, the period after which the scene repeats (0: none): the env's
    ``placement_periods()`` (a Panda task's object yaw: 90 degrees) or zeros."""
    n = len(env.placement_space.low)
    get = getattr(env, "placement_periods", None)
    return np.zeros(n) if get is None else np.asarray(get(), dtype=np.float64)


PLACEMENT_MODES = ("random", "fps", "fps-centre")


def fps_centre_dims(env) -> tuple[int, ...]:
    """The placement coordinates that ``fps-centre`` spreads: a Panda task's object x, y and yaw (the first
    three), every coordinate that varies for the other tasks."""
    from lerobot_rnd.sim.panda_scene import PANDA_TASKS

    if getattr(env, "task", None) in PANDA_TASKS:
        return (0, 1, 2)
    sp = env.placement_space
    return tuple(i for i in range(len(sp.low)) if sp.high[i] > sp.low[i])


def complete_placement(env, vec: np.ndarray, dims: Sequence[int], rng: np.random.Generator,
                       tries: int = 1000) -> np.ndarray | None:  # fmt: skip
    """``vec`` with its coordinates outside ``dims`` that vary (push-block / pick-place: the target x, y) drawn
    uniformly from their range with ``rng`` until the placement is valid, as the env's random placements draw them;
    the coordinates outside ``dims`` whose range is one value at that value. None if no valid one is found in
    ``tries`` draws (``vec``'s coordinates in ``dims`` are kept).

    The target is drawn even where the centre of its range would be valid: a rule "centre if valid, else random"
    gives demos at the edges of the object range and test placements near its centre different targets (the
    furthest-point demos of push-block mostly pushed to the centre, most test cells to random targets)."""
    sp = env.placement_space
    low, high = np.asarray(sp.low, np.float64), np.asarray(sp.high, np.float64)
    others = [i for i in range(len(low)) if i not in set(dims)]
    drawn = [i for i in others if high[i] > low[i]]
    p = np.asarray(vec, dtype=np.float64).copy()
    p[others] = (low[others] + high[others]) / 2
    if not drawn:
        return p if env.is_valid_placement(p) else None
    for _ in range(tries):
        p[drawn] = rng.uniform(low[drawn], high[drawn])
        if env.is_valid_placement(p):
            return p
    return None


class PlacementSequence:
    """Deterministic, indexable sequence of valid placements for one env (random, fps or fps-centre).

    ``fps-centre``: furthest point sampling over the coordinates :func:`fps_centre_dims` (Panda: object x, y,
    yaw; yaw compared modulo the object's symmetry, :func:`placement_periods`), starting from the centre of their
    range: the pool is that centre plus ``fps_pool - 1`` uniform draws of
    those coordinates, each completed by :func:`complete_placement` (the other coordinates, e.g. a target, drawn
    uniformly with the sequence's seeded generator until valid); the first
    placement is the centre, each next one the pool point furthest from those before, in those coordinates."""

    def __init__(self, env, mode: str = "random", seed: int = 0, fps_pool: int = 1000):
        if mode not in PLACEMENT_MODES:
            raise ValueError(f"placements must be one of {', '.join(PLACEMENT_MODES)}, got {mode!r}")
        self.env, self.mode, self.seed, self.fps_pool = env, mode, int(seed), int(fps_pool)
        self.rng = np.random.default_rng(self.seed)
        self._items: list[np.ndarray] = []
        if mode == "fps":
            pool = self._draw_valid(self.fps_pool)
            sp = env.placement_space
            order = furthest_point_order(np.stack(pool), len(pool), sp.low, sp.high, periods=placement_periods(env))
            self._items = [pool[i] for i in order]
        elif mode == "fps-centre":
            sp = env.placement_space
            low, high = np.asarray(sp.low, np.float64), np.asarray(sp.high, np.float64)
            dims = list(fps_centre_dims(env))
            centre = (low + high) / 2
            pool = []
            for i in range(self.fps_pool):
                vec = centre.copy()
                if i > 0:
                    vec[dims] = self.rng.uniform(low[dims], high[dims])
                p = complete_placement(env, vec, dims, self.rng)
                if p is not None:
                    pool.append(p)
            if not pool:
                raise RuntimeError(f"{env.task}: no valid placement in a pool of {self.fps_pool}")
            pts = np.stack(pool)
            order = furthest_point_order(pts[:, dims], len(pool), low[dims], high[dims], start=centre[dims],
                                         periods=placement_periods(env)[dims])  # fmt: skip
            self._items = [pool[i] for i in order]

    def _draw_valid(self, n: int) -> list[np.ndarray]:
        out, tries = [], 0
        while len(out) < n:
            tries += 1
            if tries > 100 * n + 1000:
                raise RuntimeError(f"{self.env.task}: could not draw {n} valid placements")
            v = self.env.sample_placement(self.rng)
            if self.env.is_valid_placement(v):
                out.append(v)
        return out

    def __getitem__(self, i: int) -> np.ndarray:
        if self.mode in ("fps", "fps-centre"):
            if i >= len(self._items):
                raise IndexError(f"placement {i} beyond the fps pool of {len(self._items)}: raise --fps-pool")
            return self._items[i]
        while len(self._items) <= i:
            self._items.extend(self._draw_valid(1))
        return self._items[i]
