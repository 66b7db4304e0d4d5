"""CFVS coarse-to-fine visual servoing for 6-DoF peg-in-hole, as a ManiSkill 3 task plugin.

Importing the package picks the rendering device (GPU, else SwiftShader on the CPU: set it
up with `cfvs-maniskill setup-render`) before SAPIEN starts, registers the UR5 robots and one env per task file in `tasks/`
(`PegInsert3DoF-v1`, ...). Vocabulary: in ManiSkill an "agent" is the robot; here the robot
lives in `robots/` and an *agent* is a policy (`agents/`).
"""

from cfvs_maniskill.rendering import device as _device

if _device.configure() == "missing":
    # One clear error now, instead of a Vulkan failure deep in the first env's creation.
    raise _device.RenderDeviceError(_device.missing_message())

from cfvs_maniskill import robots  # noqa: E402,F401  (registers the UR5 agents)

__version__ = "0.1.0"

from cfvs_maniskill.envs.registration import register_tasks as _register_tasks  # noqa: E402

TASKS = _register_tasks()
