"""Inverse kinematics of the arm for the peg tip (Pinocchio, from the articulation)."""

from __future__ import annotations

import numpy as np
import sapien

from cfvs_maniskill import geometry as G


class ArmKinematics:
    def __init__(self, robot, tcp_link: str):
        """`robot`: a ManiSkill Articulation; `tcp_link`: the name its tip link ends in."""
        articulation = robot._objs[0]
        self._pin = articulation.create_pinocchio_model()
        # Pinocchio numbers links as the articulation does; ManiSkill prefixes their names.
        limits = robot.get_qlimits()[0].cpu().numpy()
        self.qlimits = (limits[:, 0], limits[:, 1])
        names = [link.name for link in articulation.get_links()]
        self._tcp = next(i for i, n in enumerate(names) if n.endswith(tcp_link))

    def ik(self, T: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, bool]:
        """Joint positions putting the tcp at world pose T (the robot base is the world),
        searched from `seed`; (seed, False) for a non-finite T."""
        if not np.all(np.isfinite(T)):
            return seed, False
        q, ok, _ = self._pin.compute_inverse_kinematics(
            self._tcp,
            G.to_pose(T),
            initial_qpos=np.asarray(seed, np.float64),
            max_iterations=300,
        )
        if ok:
            # Pinocchio ignores joint limits; bring angles into them by whole turns, or fail.
            lo, hi = self.qlimits
            q = np.where(q > hi, q - 2 * np.pi, np.where(q < lo, q + 2 * np.pi, q))
            ok = bool(np.all((q >= lo) & (q <= hi)))
        if ok:
            ok = self._reaches(q, T)
        return np.asarray(q), bool(ok)

    def link_poses(self, q: np.ndarray, links: list[int]) -> list[np.ndarray]:
        """World poses (4x4) of the links with these articulation indices at joints q."""
        self._pin.compute_forward_kinematics(np.asarray(q, np.float64))
        return [G.to_matrix(self._pin.get_link_pose(i)) for i in links]

    def _reaches(self, q: np.ndarray, T: np.ndarray) -> bool:
        """Whether joint positions q put the tcp within 1 mm and 0.01 rad of T."""
        self._pin.compute_forward_kinematics(q)
        got = G.to_matrix(self._pin.get_link_pose(self._tcp))
        return bool(
            np.linalg.norm(got[:3, 3] - T[:3, 3]) < 1e-3
            and G.rot_angle(got[:3, :3].T @ T[:3, :3]) < 1e-2
        )


def body_pose(struct) -> sapien.Pose:
    """The pose of a ManiSkill Actor or Link straight from its SAPIEN object: the same
    float32 values as `struct.pose.sp` (which the CPU simulation reads from there too),
    without the round trip through batched tensors (50-70 us, paid several times per
    control step)."""
    if struct.scene.gpu_sim_enabled:
        return struct.pose.sp
    obj = struct._objs[0]
    return obj.entity_pose if hasattr(obj, "entity_pose") else obj.pose
