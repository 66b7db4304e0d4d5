"""Env step speed against ManiSkill's own PegInsertionSide-v1 (state obs, 1 env), and our
point-cloud observation and step against their floor: a bare SAPIEN scene with the same
camera rendering the same meshes (no ManiSkill on top), after a state-only step."""

from __future__ import annotations

import numpy as np

from benchmarks.common import Figure, interleaved


def _hold(u) -> np.ndarray:
    """The pd_joint_pos_vel action that holds our arm where it is."""
    q = u.agent.robot.get_qpos()[0].numpy()
    return np.concatenate([q, np.zeros_like(q)])


def _repeat(fn, times: int):
    """`fn` called `times` times in a row, as one timed sample."""

    def sample():
        for _ in range(times):
            fn()

    return sample


def step_ratio(steps: int = 100, rounds: int = 6) -> tuple[list[Figure], str]:
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401  (registers PegInsertionSide-v1)

    from cfvs_maniskill.rendering import device

    ours = gym.make("PegInsert6DoF-v1", obs_mode="state")
    ours.reset(seed=0)
    theirs = gym.make(
        "PegInsertionSide-v1", obs_mode="state", render_backend=device.render_backend()
    )
    theirs.reset(seed=0)
    u = ours.unwrapped
    hold = _hold(u)
    zero = np.zeros(theirs.action_space.shape, dtype=np.float32)  # pd_joint_delta_pos
    runs = {"ours": lambda: ours.step(hold), "theirs": lambda: theirs.step(zero)}
    t = interleaved({k: _repeat(f, steps) for k, f in runs.items()}, rounds)
    n = steps * rounds
    ms = {k: 1000 * v / n for k, v in t.items()}
    sub = {k: e.unwrapped.sim_freq // e.unwrapped.control_freq for k, e in
           (("ours", ours), ("theirs", theirs))}  # fmt: skip
    ours.close()
    theirs.close()
    ratio = ms["theirs"] / ms["ours"]
    detail = (
        f"state obs, 1 env, {n} steps each, interleaved: ours {ms['ours']:.2f} ms/step "
        f"({sub['ours']} PhysX substeps, UR5 + peg + hole object), PegInsertionSide-v1 "
        f"{ms['theirs']:.2f} ms/step ({sub['theirs']} substeps, Panda + peg + box)"
    )
    fig = Figure(
        "env step speed: ours / ManiSkill PegInsertionSide-v1 (state obs, 1 env)",
        f"{ratio:.2f}",
        ">= 0.8",
        ratio >= 0.8,
        f"{ms['ours']:.2f} vs {ms['theirs']:.2f} ms/step",
    )
    return [fig], detail


def _bare_scene(u):
    """A plain SAPIEN scene with what our wrist camera sees: the robot (same URDF and
    joint angles), the table, the current hole object, ManiSkill's default lights, and
    the same camera (size, fov, near/far, mount pose) on the same link."""
    import sapien

    from cfvs_maniskill.robots.ur5 import CAMERA_FOV, TOOL_LINK, camera_pose_in_tool

    scene = sapien.Scene(
        [sapien.physx.PhysxCpuSystem(), sapien.render.RenderSystem(u._render_device)]
    )
    scene.set_ambient_light([0.3, 0.3, 0.3])
    scene.add_directional_light([1, 1, -1], [1, 1, 1])
    scene.add_directional_light([0, 0, -1], [1, 1, 1])
    robot = scene.create_urdf_loader().load(str(u.agent.urdf_path))
    robot.set_qpos(u.agent.robot.get_qpos()[0].numpy())
    b = scene.create_actor_builder()
    b.add_box_visual(half_size=[1.0, 1.0, 0.025])
    b.build_static().set_pose(sapien.Pose(p=[0.3, 0, -0.025]))
    visual, _ = u.geometries[u.object_index].mesh_files()
    b = scene.create_actor_builder()
    b.add_visual_from_file(str(visual))
    hole = b.build_kinematic()
    hole.set_pose(u.hole_objects[u.object_index].pose.sp)
    tool = next(link for link in robot.get_links() if link.name == TOOL_LINK)
    # The wrist camera's shader: SAPIEN's default is global and was last set by whichever
    # camera ManiSkill built before (the env's lit render cameras use "default").
    sapien.render.set_camera_shader_dir("minimal")
    cam = scene.add_mounted_camera(
        "floor_camera", tool.entity, camera_pose_in_tool(),
        u.task.camera_width, u.task.camera_height, CAMERA_FOV, 0.01, 2.0,
    )  # fmt: skip
    return scene, cam


def _raw_render(scene, cam):
    """The same pictures our observation holds (colour, position + segmentation), turned
    into world-frame points: the least any point-cloud observation must do."""

    def render():
        scene.update_render()
        cam.take_picture()
        rgb = cam.get_picture("Color")
        ps = cam.get_picture("PositionSegmentation")
        xyz = ps[..., :3].reshape(-1, 3).astype(np.float32) / 1000.0
        world = xyz @ cam.get_model_matrix()[:3, :3].T + cam.get_model_matrix()[:3, 3]
        return world, rgb, ps[..., 3]

    return render


def pointcloud_floor(rounds: int = 200) -> tuple[list[Figure], str]:
    """Our point-cloud observation, and a whole point-cloud step (physics, observation,
    reward, info), each against its floor: the bare render, and a state-only step of the
    same env plus the bare render."""
    import gymnasium as gym

    env = gym.make("PegInsert6DoF-v1", obs_mode="pointcloud")
    env.reset(seed=0)
    state = gym.make("PegInsert6DoF-v1", obs_mode="state")
    state.reset(seed=0)
    u = env.unwrapped
    scene, cam = _bare_scene(u)
    render = _raw_render(scene, cam)
    hold = _hold(u)

    def step_floor():
        state.step(hold)
        render()

    # One observation at a time, alternating scenes as an episode does; steps in samples
    # of ten, each with its physics between the renders.
    timed = {"obs": u.get_obs, "render": render}
    steps = {"step": _repeat(lambda: env.step(hold), 10), "step_floor": _repeat(step_floor, 10)}
    for f in (*timed.values(), *steps.values()):
        f()  # first frames: shader and pipeline set-up
    ms = {k: 1000 * v / rounds for k, v in interleaved(timed, rounds).items()}
    n = rounds // 10 * 10
    ms |= {k: 1000 * v / n for k, v in interleaved(steps, rounds // 10).items()}
    env.close()
    state.close()
    obs_ratio, step_ratio_ = ms["obs"] / ms["render"], ms["step"] / ms["step_floor"]
    w, h = u.task.camera_width, u.task.camera_height
    detail = (
        f"{w}x{h} wrist camera, {rounds} samples each, interleaved: our pointcloud obs "
        f"{ms['obs']:.2f} ms, bare SAPIEN render + read-back + world transform "
        f"{ms['render']:.2f} ms; a pointcloud step {ms['step']:.2f} ms, a state step plus "
        f"that render {ms['step_floor']:.2f} ms"
    )
    figs = [
        Figure(
            "pointcloud obs time: ours / bare SAPIEN scene, same camera and meshes",
            f"{obs_ratio:.2f}",
            "<= 1.2",
            obs_ratio <= 1.2,
            f"{ms['obs']:.1f} vs {ms['render']:.1f} ms",
        ),
        Figure(
            "pointcloud step time: ours / a state step + the bare render",
            f"{step_ratio_:.2f}",
            "<= 1.2",
            step_ratio_ <= 1.2,
            f"{ms['step']:.1f} vs {ms['step_floor']:.1f} ms",
        ),
    ]
    return figs, detail
