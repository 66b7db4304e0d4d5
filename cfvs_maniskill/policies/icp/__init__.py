"""The paper's ICP baselines: a model of the hole registered to the wrist cloud by
point-to-plane ICP, started from the workspace centre (`icp`) or from OAKN's keypoints
(`icp_kpts`)."""

from cfvs_maniskill.policies.base import AgentEntry

CLASS = "cfvs_maniskill.policies.icp.agent:ICPAgent"


def _factory(init: str):
    def make(task):
        from cfvs_maniskill.policies.icp.agent import ICPAgent, ICPConfig

        return ICPAgent(task, ICPConfig(init=init))

    return make


AGENTS = {
    "icp": AgentEntry(CLASS, _factory("workspace")),
    "icp_kpts": AgentEntry(CLASS, _factory("oakn")),
}
