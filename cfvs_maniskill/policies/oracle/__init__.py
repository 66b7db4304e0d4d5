"""The oracle: true poses, ideal moves. The ceiling of the task, not an agent a robot could
run (it reads the env)."""

from cfvs_maniskill.policies.base import AgentEntry

CLASS = "cfvs_maniskill.policies.oracle.agent:OracleAgent"


def _make(env):
    from cfvs_maniskill.policies.oracle.agent import OracleAgent

    return OracleAgent(env)


AGENTS = {"oracle": AgentEntry(CLASS, _make, privileged=True)}
