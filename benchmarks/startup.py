"""Time from `import cfvs_maniskill` to the first observation in a new process, split into
import, env build and first observation (the renderer's shader compile), beside a bare
SAPIEN scene's first frame in a new process (the compile alone)."""

from __future__ import annotations

import json
import subprocess
import sys

from benchmarks.common import Figure

_OURS = """
import json, time
t0 = time.perf_counter()
import cfvs_maniskill, gymnasium as gym
t1 = time.perf_counter()
env = gym.make("PegInsert6DoF-v1", obs_mode="pointcloud", render_mode=None)
t2 = time.perf_counter()  # the env's build includes its first reset and observation
obs, _ = env.reset(seed=1)
t3 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "make": t2 - t1, "reset": t3 - t2, "total": t3 - t0}))
"""

_BARE = """
import json, time
import cfvs_maniskill  # only for the SwiftShader device set-up
import sapien
from cfvs_maniskill.rendering import device
from mani_skill.envs.utils.system.backend import parse_sim_and_render_backend
dev = parse_sim_and_render_backend("physx_cpu", device.render_backend()).render_device
scene = sapien.Scene([sapien.physx.PhysxCpuSystem(), sapien.render.RenderSystem(dev)])
b = scene.create_actor_builder(); b.add_box_visual(half_size=[0.1, 0.1, 0.1]); b.build_static()
sapien.render.set_camera_shader_dir("minimal")
cam = scene.add_camera("c", 128, 128, 1.2, 0.01, 10)
t0 = time.perf_counter()
scene.update_render(); cam.take_picture(); cam.get_picture("PositionSegmentation")
print(json.dumps({"first_frame": time.perf_counter() - t0}))
"""


def _py(code: str) -> dict:
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if r.returncode:
        raise RuntimeError(r.stderr[-2000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def measure() -> tuple[list[Figure], str]:
    ours, bare = _py(_OURS), _py(_BARE)
    detail = (
        f"New process, PegInsert6DoF pointcloud: import {ours['import']:.1f} s, env build "
        f"incl. the first observation {ours['make']:.1f} s, a further reset "
        f"{ours['reset']:.2f} s. A bare SAPIEN scene's first 128x128 frame with the same "
        f"(minimal) shader in a new process: {bare['first_frame']:.1f} s: SwiftShader "
        "compiling the shaders, once per process (eval workers pay it once)."
    )
    fig = Figure(
        "time from import to first observation, new process",
        f"{ours['total']:.1f} s",
        "report",
        None,
        f"of which {bare['first_frame']:.1f} s is the renderer's first-frame compile",
    )
    return [fig], detail
