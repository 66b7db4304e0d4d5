"""The KOVIS baseline (keypoint-based visual servoing from stereo images): its agent
(`agent.py`), network (`model.py`), rollout collection (`collect.py`), training
(`train.py`) and servo diagnosis (`diagnose.py`); the shipped weights are in
agents/kovis/, whose README says how they were made."""

from cfvs_maniskill.policies.base import AgentEntry

CLASS = "cfvs_maniskill.policies.kovis.agent:KOVISAgent"


def _make(task):
    from cfvs_maniskill.policies.kovis.agent import KOVISAgent

    return KOVISAgent(task)


AGENTS = {"kovis": AgentEntry(CLASS, _make)}
