"""A complete agent of your own (docs/your-own-agent.md): the hole is taken to be the middle
of the object's top face. Right for centred holes in upright parts (3-DoF), wrong elsewhere.

    python -m cfvs_maniskill.eval --agents examples.top_face_agent:TopFaceAgent cfvs \
        --tasks PegInsert3DoF --out results/mine
"""

import numpy as np

from cfvs_maniskill.perception.clouds import object_points, tool_to_world
from cfvs_maniskill.policies.base import Action, Agent, Observation
from cfvs_maniskill.policies.interface import TaskSpec, insertion_pose


class TopFaceAgent(Agent):
    name = "top_face"
    obs_mode = "pointcloud"  # the wrist cloud (world frame, w = 0: no return)

    def __init__(self, task: TaskSpec):
        self.task, self.moved = task, False

    def reset(self, seed: int) -> None:
        self.moved = False

    def act(self, o: Observation) -> Action:
        if self.moved:
            return Action.insert()
        xyzw = np.asarray(o.obs["pointcloud"]["xyzw"][0])
        pts = tool_to_world(object_points(xyzw, o.tcp_pose, self.task.peg), o.tcp_pose)
        if len(pts) < 50:
            return Action.give_up("nothing but the table in view")
        top = pts[pts[:, 2] > pts[:, 2].max() - 0.004]  # the highest face
        hole = np.eye(4)
        hole[:3, 3] = [*top[:, :2].mean(axis=0), top[:, 2].max()]
        self.moved = True
        return Action.move(insertion_pose(self.task.peg, hole, -0.03, o.tcp_pose))
