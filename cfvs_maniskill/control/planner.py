"""Collision-free joint paths against what the robot knows: the table's plane and the
occupancy of every wrist cloud seen this episode (voxels), with the IK branch chosen for a
free path. The executor asks for one only when its straight Cartesian line would touch a
known obstacle or is not followable, so moves in free space stay straight lines.

The search is RRT-Connect (Kuffner & LaValle 2000) with shortcutting, in numpy with a
generator seeded by the query itself: ManiSkill's planner (mplib 0.1.1) crashes under
numpy 2, and OMPL's Python bindings draw from one process-wide seed, so an episode's path
would depend on what the worker ran before it.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from cfvs_maniskill.perception.clouds import object_points, tool_to_world
from cfvs_maniskill.robots.collision import ArmCollision


@dataclass
class PlannerConfig:
    margin: float = 0.01
    """Clearance kept from known points and the table, m (a voxel's half diagonal less)."""
    voxel: float = 0.01
    """Occupancy resolution, m."""
    small_move: float = 0.02
    """Moves of the tcp shorter than this (m, and turning under 5 deg) stay straight lines
    without a check: the fine stage's corrections near the part it is servoing to."""
    extend: float = 0.15
    """Longest RRT extension, rad (joint-space distance)."""
    check_step: float = 0.008
    """Joint-space spacing at which an edge is checked, rad: under the margin at the
    peg's tip, about 1 m from the shoulder."""
    max_samples: int = 3000
    """Random configurations tried before the search gives up."""
    goal_seeds: int = 12
    """IK starts for the goal: the current joints, then random ones (other arm branches)."""
    shortcuts: int = 80
    """Random shortcut attempts on a found path."""


_BITS = 21
_BIAS = 1 << (_BITS - 1)


def _pack(keys: np.ndarray) -> np.ndarray:
    """(N, 3) voxel indices -> one int64 each."""
    k = keys + _BIAS
    return (k[:, 0] << (2 * _BITS)) | (k[:, 1] << _BITS) | k[:, 2]


def _unpack(packed: np.ndarray) -> np.ndarray:
    mask = (1 << _BITS) - 1
    k = np.column_stack([packed >> (2 * _BITS), (packed >> _BITS) & mask, packed & mask])
    return k - _BIAS


class KnownWorld:
    """Occupied voxels from the wrist clouds of this episode (world frame), without the
    table (a known plane) and the peg; what the planner avoids."""

    def __init__(self, voxel: float):
        self.voxel = voxel
        self.clear()

    def clear(self) -> None:
        self._keys = np.zeros(0, np.int64)
        self.points = np.zeros((0, 3))
        self.tree: cKDTree | None = None

    def add_points(self, world: np.ndarray) -> None:
        """Add points (world frame) to the occupied voxels."""
        keys = np.floor(world / self.voxel).astype(np.int64)
        # One integer per voxel (21 bits an axis: +-10 km at 1 cm): a 1-D unique is far
        # cheaper than np.unique(axis=0) on rows.
        packed = np.unique(np.concatenate([self._keys, _pack(keys)]))
        if len(packed) == len(self._keys):
            return
        self._keys = packed
        self.points = (_unpack(packed) + 0.5) * self.voxel
        self.tree = cKDTree(self.points)


class PathPlanner:
    def __init__(self, collision: ArmCollision, ik, limits, cfg: PlannerConfig | None = None):
        """`ik(T, seed) -> (q, ok)`: the robot's IK; `limits`: (low, high) joint arrays."""
        self.collision = collision
        self.ik = ik
        self.low, self.high = (np.asarray(a, np.float64) for a in limits)
        self.cfg = cfg or PlannerConfig()
        self.world = KnownWorld(self.cfg.voxel)
        self._seen: list = []

    def observe(self, obs, q: np.ndarray, tcp: np.ndarray, peg: str) -> None:
        """Note a pointcloud observation taken at joints q (other observation modes add
        nothing); its points join the known world when a check first needs them."""
        cloud = obs.get("pointcloud") if isinstance(obs, dict) else None
        if cloud is not None and "xyzw" in cloud:
            self._seen.append((cloud["xyzw"][0].cpu().numpy(), q.copy(), tcp.copy(), peg))

    def know(self, world: np.ndarray) -> None:
        """Obstacle points (world frame) known without looking: they join the known world."""
        self.world.add_points(world)

    def forget(self) -> None:
        """A new episode: nothing is known but the table."""
        self.world.clear()
        self._seen = []

    def _update(self) -> None:
        """What the noted observations saw, except the table and the arm itself."""
        for xyzw, q, tcp, peg in self._seen:
            world = tool_to_world(object_points(xyzw, tcp, peg), tcp)
            self.world.add_points(world[~self.collision.on_arm(q, world, 2 * self.cfg.margin)])
        self._seen = []

    def blocked_by(self, q: np.ndarray) -> str | None:
        """The link of configuration q that would touch a known obstacle, or None."""
        hit = self._first_blocked([q])
        return None if hit is None else hit[1]

    def _first_blocked(self, qs: list[np.ndarray]) -> tuple[int, str] | None:
        if self._seen:
            self._update()
        w = self.world
        return self.collision.first_touch(qs, w.points, w.tree, self.cfg.margin)

    def _all_free(self, qs: list[np.ndarray]) -> bool:
        return self._first_blocked(qs) is None

    def _edge_configurations(self, a: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
        """The configurations an edge is checked at: every `check_step`, b included."""
        n = max(1, int(np.ceil(np.abs(b - a).max() / self.cfg.check_step)))
        return [a + (b - a) * i / n for i in range(1, n + 1)]

    def edge_free(self, a: np.ndarray, b: np.ndarray) -> bool:
        return self._all_free(self._edge_configurations(a, b))

    def path_free(self, path: list[np.ndarray]) -> bool:
        edges = zip(path[:-1], path[1:], strict=True)
        return self._all_free([q for a, b in edges for q in self._edge_configurations(a, b)])

    def plan(self, q0: np.ndarray, target: np.ndarray) -> list[np.ndarray] | None:
        """A collision-free joint path from q0 to a configuration putting the tcp at
        `target` (4x4), or None (the start or every goal configuration is blocked, or no
        path was found)."""
        seed = hashlib.sha256(np.concatenate([q0, target.ravel()]).tobytes()).digest()
        rng = np.random.default_rng(int.from_bytes(seed[:8], "little"))
        if self.blocked_by(q0) is not None:
            return None
        goals = []
        for k in range(self.cfg.goal_seeds):
            start = q0 if k == 0 else rng.uniform(self.low, self.high)
            q, ok = self.ik(target, start)
            if ok and self.blocked_by(q) is None:
                goals.append(q)
        for goal in sorted(goals, key=lambda g: float(np.abs(g - q0).sum())):
            path = self._connect(q0, goal, rng)
            if path is not None:
                return self._shortcut(path, rng)
        return None

    def _connect(self, q0: np.ndarray, goal: np.ndarray, rng) -> list[np.ndarray] | None:
        if self.edge_free(q0, goal):
            return [q0, goal]
        start_tree = ([q0], [None])  # (nodes, parent index)
        trees = start_tree, ([goal], [None])
        for _ in range(self.cfg.max_samples):
            sample = rng.uniform(self.low, self.high)
            grow, other = trees
            i = self._extend(grow, sample)
            if i is not None:
                j = self._reach(other, grow[0][i])
                if j is not None:
                    a, b = self._branch(grow, i), self._branch(other, j)
                    path = a[::-1] + b[1:]  # root of `grow` ... meeting point ... root of `other`
                    return path if grow is start_tree else path[::-1]
            trees = trees[1], trees[0]
        return None

    def _extend(self, tree, sample: np.ndarray) -> int | None:
        """One step from the tree's nearest node towards `sample`; the new node or None."""
        nodes, parents = tree
        near = int(np.argmin([np.abs(n - sample).max() for n in nodes]))
        d = sample - nodes[near]
        step = np.abs(d).max()
        new = nodes[near] + d * min(1.0, self.cfg.extend / max(step, 1e-12))
        if not self.edge_free(nodes[near], new):
            return None
        nodes.append(new)
        parents.append(near)
        return len(nodes) - 1

    def _reach(self, tree, target: np.ndarray) -> int | None:
        """Extend the tree towards `target` until it gets there (its index) or is blocked."""
        while True:
            i = self._extend(tree, target)
            if i is None:
                return None
            if np.abs(tree[0][i] - target).max() < 1e-9:
                return i

    @staticmethod
    def _branch(tree, i: int) -> list[np.ndarray]:
        """Nodes from node i back to the tree's root."""
        nodes, parents = tree
        out = []
        while i is not None:
            out.append(nodes[i])
            i = parents[i]
        return out

    def _shortcut(self, path: list[np.ndarray], rng) -> list[np.ndarray]:
        for _ in range(self.cfg.shortcuts):
            if len(path) < 3:
                break
            i, j = sorted(rng.choice(len(path), 2, replace=False))
            if j - i > 1 and self.edge_free(path[i], path[j]):
                path = path[: i + 1] + path[j:]
        return path
