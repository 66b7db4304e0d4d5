"""Run one of ManiSkill's own command-line tools with this package's envs registered.

    python -m cfvs_maniskill.tool replay_trajectory --traj-path demos/trajectory.h5 ...
    python -m cfvs_maniskill.tool demo_random_action -e PegInsert6DoF-v1
    python -m cfvs_maniskill.tool mani_skill.utils.download_demo --help   # any module

ManiSkill's tools call `gym.make(env_id)` with the id stored in a trajectory's .json (or
given on the command line), and our envs exist only once `cfvs_maniskill` is imported. Where
a tool takes an env id, gymnasium's `module:EnvId` form does that import too
(`-e cfvs_maniskill:PegInsert6DoF-v1`); a stored id such as `PegInsert6DoF-v1` needs this
wrapper. The tool runs exactly as `python -m <module>` would, with the same arguments.
"""

from __future__ import annotations

import importlib.util
import runpy
import sys

SHORT_NAMES = {
    "replay_trajectory": "mani_skill.trajectory.replay_trajectory",
    "demo_random_action": "mani_skill.examples.demo_random_action",
    "merge_trajectory": "mani_skill.trajectory.merge_trajectory",
}
"""Short names of the tools the README shows; any other importable module also works."""


def main(argv: list[str]) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        print("\nshort names: " + ", ".join(f"{k} -> {v}" for k, v in SHORT_NAMES.items()))
        return 0 if argv else 2
    module = SHORT_NAMES.get(argv[0], argv[0])

    try:
        found = importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        found = False
    if not found:
        names = ", ".join(SHORT_NAMES)
        print(f"error: no module '{module}'; expected one of {names} or a module path")
        return 2
    sys.argv = [module, *argv[1:]]
    runpy.run_module(module, run_name="__main__", alter_sys=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
