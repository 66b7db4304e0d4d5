"""Agent names for `--agent`, each a factory taking the env."""

from __future__ import annotations

from collections.abc import Callable

from cfvs_maniskill.agents.base import Agent


def _oracle(env) -> Agent:
    from cfvs_maniskill.agents.oracle import OracleAgent

    return OracleAgent(env)


AGENTS: dict[str, Callable[..., Agent]] = {"oracle": _oracle}
AGENT_OBS_MODES = {"oracle": "state"}
DEFAULT_AGENT = "oracle"
"""Until CFVS weights ship, the run command's default is the oracle."""


def make_agent(name: str, env) -> Agent:
    if name not in AGENTS:
        raise KeyError(f"unknown agent '{name}'; valid: {', '.join(AGENTS)}")
    return AGENTS[name](env)
