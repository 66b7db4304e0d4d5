"""CFVS, the paper's coarse-to-fine agent: its configuration (`config.py`), the agent
(`agent.py`), the networks OAKN (coarse, `oakn.py`) and OPN (fine, `opn.py`), their
datasets (`collect.py`) and training (`train.py`); the shipped weights are in agents/cfvs/.

Agent names: `cfvs`, `cfvs_<ablation>` (a key of config.ABLATIONS) and `cfvs@DIR` (CFVS with
the trained networks in DIR)."""

from __future__ import annotations

from pathlib import Path

from cfvs_maniskill.policies.base import AgentEntry
from cfvs_maniskill.policies.cfvs.config import ABLATIONS

CLASS = "cfvs_maniskill.policies.cfvs.agent:CFVSAgent"
PAPER_ABLATIONS = ("no_c2f", "no_map", "aug", "no_rim")
"""Table IV's ablations (augmentation runs the other way: the shipped nets are trained
without it), and the paper's own fine stage (OPN's tilt): listed agents. Every other key
of ABLATIONS is an agent too, `cfvs_<key>`, made on request (`resolve`)."""
WEIGHTS_PREFIX = "cfvs@"
"""`cfvs@DIR`: the CFVS agent with the trained networks in DIR (laid out like
agents/cfvs/: a tasks.yaml, or <peg>/oakn.pt and <peg>/opnv.pt), e.g. weights you trained;
DIR is a path or a folder's name in the user folder's agents/cfvs/ (resources.py)."""


def entry(name: str = "cfvs", weights: str = "", ablation: str = "") -> AgentEntry:
    """CFVS, or its `ablation` (a key of ABLATIONS); `weights`: a weights folder (its
    tasks.yaml says which files) instead of the shipped one."""

    def make(task):
        from cfvs_maniskill.policies.cfvs.agent import CFVSAgent
        from cfvs_maniskill.policies.cfvs.config import CFVSConfig, ablation_config

        cfg = ablation_config(ablation) if ablation else CFVSConfig()
        if weights:
            cfg.weights_dir = Path(weights)
        agent = CFVSAgent(task, cfg)
        agent.name = name
        return agent

    return AgentEntry(CLASS, make)


AGENTS = {"cfvs": entry(), **{f"cfvs_{a}": entry(f"cfvs_{a}", ablation=a) for a in PAPER_ABLATIONS}}


def ablation_names() -> list[str]:
    """`cfvs_<ablation>` for every ablation, listed in AGENTS or not."""
    return [f"cfvs_{a}" for a in ABLATIONS]


def resolve(name: str) -> AgentEntry | None:
    """An ablation's or a weights folder's name (`cfvs_<key>`, `cfvs@DIR`) -> its entry;
    None for a name that is neither; KeyError naming a weights folder that is not there."""
    if name in ablation_names():
        return entry(name, ablation=name.removeprefix("cfvs_"))
    if not name.startswith(WEIGHTS_PREFIX):
        return None
    from cfvs_maniskill import resources

    spec = name[len(WEIGHTS_PREFIX) :]
    folder = resources.find("agents", spec, "", sub="cfvs")
    if folder is None or not folder.is_dir():
        raise KeyError(
            f"agent '{name}': no weights folder '{spec}' (a path, or a folder name in "
            f"{' or '.join(str(d) for d in resources.search_dirs('agents', 'cfvs'))})"
        )
    return entry(name, weights=str(folder.resolve()))


HELP = (
    f"the CFVS ablations {', '.join(n for n in ablation_names() if n not in AGENTS)}, "
    f"{WEIGHTS_PREFIX}DIR (CFVS with the weights in DIR)"
)
"""The names `resolve` takes, for the registry's error message."""
