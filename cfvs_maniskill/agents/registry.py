"""Agent names for `--agent`, each a factory taking the env."""

from __future__ import annotations

from collections.abc import Callable

from cfvs_maniskill.agents.base import Agent


def _oracle(env) -> Agent:
    from cfvs_maniskill.agents.oracle import OracleAgent

    return OracleAgent(env)


def _cfvs(**switches) -> Callable[..., Agent]:
    def make(env) -> Agent:
        from cfvs_maniskill.agents.cfvs import CFVSAgent, CFVSConfig

        agent = CFVSAgent(env, CFVSConfig(**switches))
        if switches:
            agent.name = "cfvs_" + "_".join(f"no_{k}" for k in switches)
        return agent

    return make


def _icp(init: str) -> Callable[..., Agent]:
    def make(env) -> Agent:
        from cfvs_maniskill.agents.icp import ICPAgent, ICPConfig

        return ICPAgent(env, ICPConfig(init=init))

    return make


def _hole_detect(env) -> Agent:
    from cfvs_maniskill.agents.hole_detect import HoleDetectAgent

    return HoleDetectAgent(env)


def _kovis(env) -> Agent:
    from cfvs_maniskill.agents.kovis import KOVISAgent

    return KOVISAgent(env)


AGENTS: dict[str, Callable[..., Agent]] = {
    "cfvs": _cfvs(),
    # The paper's ablations (Table IV).
    "cfvs_no_c2f": _cfvs(coarse_to_fine=False),
    "cfvs_no_map": _cfvs(confidence_map=False),
    "cfvs_no_aug": _cfvs(augmentation=False),
    "cfvs_aug": _cfvs(augmentation=True),
    # The paper's baselines (Table II).
    "icp": _icp("workspace"),
    "icp_kpts": _icp("oakn"),
    "3drhd": _hole_detect,
    "kovis": _kovis,
    "oracle": _oracle,
}
AGENT_OBS_MODES = {"oracle": "state", "kovis": "rgbd"}
"""Agents not listed here see the wrist point cloud."""
DEFAULT_AGENT = "cfvs"


def make_agent(name: str, env) -> Agent:
    if name not in AGENTS:
        raise KeyError(f"unknown agent '{name}'; valid: {', '.join(AGENTS)}")
    return AGENTS[name](env)
