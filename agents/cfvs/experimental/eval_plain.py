"""One-off (session 9): CFVS with the weights in WEIGHTS_DIR, the paper's protocol (no
search), 15 cm, the test objects, 25 each, the scenes of results/sensing_plain.

usage: python eval_plain.py WEIGHTS_DIR SENSOR TASK [TASK ...]"""

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from cfvs_maniskill.agents.cfvs import CFVSAgent, CFVSConfig
from cfvs_maniskill.agents.executor import Executor, ExecutorConfig
from cfvs_maniskill.agents.interface import TaskSpec
from cfvs_maniskill.episode import run_episode
from cfvs_maniskill.eval.jobs import scene_seed

OBJECTS = ["cuboid_test_1", "cuboid_test_2", "cylinder", "pentagonal_prism"]

torch.set_num_threads(1)
weights, sensor, tasks = Path(sys.argv[1]), sys.argv[2], sys.argv[3:]
for task in tasks:
    env = gym.make(f"{task}-v1", obs_mode="pointcloud", sensor=sensor, objects=OBJECTS)
    agent = CFVSAgent(TaskSpec.of(env.unwrapped.task), CFVSConfig(weights_dir=weights))
    executor = Executor(env, ExecutorConfig(search_radius=0.0))
    ok, last = 0, []
    for obj in OBJECTS:
        for i in range(25):
            seed = scene_seed(task, obj, "small", i, 0)
            r = run_episode(env, agent, executor, seed, options={"object": obj})
            ok += r.success
            last.append(r.move_residuals[-1] if r.move_residuals else [np.nan, np.nan])
    p50, p90 = np.nanpercentile(np.array(last)[:, 0], [50, 90])
    print(task, sensor, f"{ok}/100", f"last lateral p50/p90 {p50:.1f}/{p90:.1f} mm", flush=True)
