"""The paper's 3DRHD baseline: the hole found as a gap in the fitted top face of the cloud."""

from cfvs_maniskill.policies.base import AgentEntry

CLASS = "cfvs_maniskill.policies.hole_detect.agent:HoleDetectAgent"


def _make(task):
    from cfvs_maniskill.policies.hole_detect.agent import HoleDetectAgent

    return HoleDetectAgent(task)


AGENTS = {"3drhd": AgentEntry(CLASS, _make)}
