"""CFVS coarse-to-fine visual servoing for 6-DoF peg-in-hole, as a ManiSkill 3 task plugin.

Importing the package registers one gym env id per task file in `tasks/`
(`PegInsert3DoF-v1`, ...) and loads nothing heavy: the simulator (ManiSkill, SAPIEN, torch)
and the rendering device (a GPU, else SwiftShader on the CPU: set it up with
`cfvs-maniskill setup-render`) are chosen when an env is first made. Vocabulary: in
ManiSkill an "agent" is the robot; here the robot lives in `robots/` and an *agent* is a
policy (`policies/`).
"""

import warnings
from importlib import metadata as _metadata

from cfvs_maniskill.envs.registration import register_tasks as _register_tasks

try:  # written once, in pyproject.toml: a release changes no code the records fingerprint
    __version__ = _metadata.version("cfvs_maniskill")
except _metadata.PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"

# SAPIEN falls back to its bundled Vulkan loader, which works; its warning only confuses.
warnings.filterwarnings("ignore", message="Failed to find system libvulkan")

TASKS = _register_tasks()
"""Every registered task by name (bundled and in the user folder) -> its TaskConfig."""
