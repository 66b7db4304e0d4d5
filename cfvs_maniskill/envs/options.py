"""The env's own gym.make options, checked against its task: an error names the option."""

from __future__ import annotations

from cfvs_maniskill.envs.task_config import TaskConfig
from cfvs_maniskill.sensing.profile import SensorProfile


def check_options(cfg: TaskConfig, obs_mode: str, stereo: bool, num_envs: int) -> None:
    if stereo and "pointcloud" in obs_mode:
        raise ValueError(
            f"{cfg.env_id}: stereo=True adds the wrist camera's two stereo imagers for "
            "image agents; with obs_mode 'pointcloud' their points would be merged into "
            "the wrist cloud. Use an image obs mode (rgbd, rgb, rgb+depth)"
        )
    if num_envs != 1:
        raise ValueError(
            f"{cfg.env_id}: num_envs={num_envs} is not supported: the task's scene "
            "sampling, evaluation and observation noise are single-scene (numpy) code. "
            "Run many episodes in parallel with the evaluation's workers "
            "(`python -m cfvs_maniskill.eval --workers N`) or a vector of single envs "
            "(gymnasium.vector.AsyncVectorEnv of gym.make(..., num_envs=1))"
        )


def start_distance(cfg: TaskConfig, init_error: str | float) -> float:
    """The peg tip's start distance from the hole, m: a name of the task's (small, large)
    or a number."""
    if not isinstance(init_error, str):
        return float(init_error)
    if init_error not in cfg.init_error:
        raise ValueError(
            f"unknown init_error '{init_error}'; valid: {', '.join(cfg.init_error)} "
            "or a distance in metres"
        )
    return cfg.init_error[init_error]


def depth_noise(cfg: TaskConfig, profile: SensorProfile, override: float | None) -> float:
    """Per-point depth noise of an iid model, m: the option, else the profile's, else the
    task file's."""
    if override is not None:
        return override
    return cfg.depth_noise_std if profile.depth.std is None else profile.depth.std
