"""Agent names for `--agent`, each a factory taking the task's nominal constants (TaskSpec).

Only the oracle's factory takes the env (it reads true poses: the ceiling, not an agent a
robot could run); `make_agent` hands the env to nothing else."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from cfvs_maniskill.agents.base import Action, Agent, AgentFailure, Observation
from cfvs_maniskill.agents.interface import TaskSpec


def _oracle(env) -> Agent:
    from cfvs_maniskill.agents.oracle import OracleAgent

    return OracleAgent(env)


def _cfvs(name: str = "cfvs", weights: str = "", ablation: str = "") -> Callable[..., Agent]:
    """CFVS, or its `ablation` (a key of cfvs.ABLATIONS); `weights`: a weights folder (its
    tasks.yaml says which files) instead of the shipped one."""

    def make(task: TaskSpec) -> Agent:
        from cfvs_maniskill.agents.cfvs import CFVSAgent, CFVSConfig, ablation_config

        cfg = ablation_config(ablation) if ablation else CFVSConfig()
        if weights:
            cfg.weights_dir = Path(weights)
        agent = CFVSAgent(task, cfg)
        agent.name = name
        return agent

    return make


def _icp(init: str) -> Callable[..., Agent]:
    def make(task: TaskSpec) -> Agent:
        from cfvs_maniskill.agents.icp import ICPAgent, ICPConfig

        return ICPAgent(task, ICPConfig(init=init))

    return make


def _hole_detect(task: TaskSpec) -> Agent:
    from cfvs_maniskill.agents.hole_detect import HoleDetectAgent

    return HoleDetectAgent(task)


def _kovis(task: TaskSpec) -> Agent:
    from cfvs_maniskill.agents.kovis import KOVISAgent

    return KOVISAgent(task)


PAPER_ABLATIONS = ("no_c2f", "no_map", "aug", "no_rim")
"""Table IV's ablations (augmentation runs the other way: the shipped nets are trained
without it), and the paper's own fine stage (OPN's tilt): listed agents. Every other key
of cfvs.ABLATIONS is an agent too, `cfvs_<key>`, made on request (ablation_names())."""

AGENTS: dict[str, Callable[..., Agent]] = {
    "cfvs": _cfvs(),
    **{f"cfvs_{a}": _cfvs(f"cfvs_{a}", ablation=a) for a in PAPER_ABLATIONS},
    # The paper's baselines (Table II).
    "icp": _icp("workspace"),
    "icp_kpts": _icp("oakn"),
    "3drhd": _hole_detect,
    "kovis": _kovis,
    "oracle": _oracle,
}
BUILTIN_CLASSES = {
    "cfvs": "cfvs_maniskill.agents.cfvs:CFVSAgent",
    "icp": "cfvs_maniskill.agents.icp:ICPAgent",
    "icp_kpts": "cfvs_maniskill.agents.icp:ICPAgent",
    "3drhd": "cfvs_maniskill.agents.hole_detect:HoleDetectAgent",
    "kovis": "cfvs_maniskill.agents.kovis:KOVISAgent",
    "oracle": "cfvs_maniskill.agents.oracle:OracleAgent",
}
"""The class behind each built-in factory (CFVS's ablations and `cfvs@DIR` are CFVSAgent):
its `obs_mode` and `env_options` say what the env must give it."""
DEFAULT_AGENT = "cfvs"
PRIVILEGED = {"oracle"}
"""Factories that take the env itself (they read the truth)."""


WEIGHTS_PREFIX = "cfvs@"
"""`cfvs@DIR`: the CFVS agent with the trained networks in DIR (laid out like
agents/cfvs/: a tasks.yaml, or <peg>/oakn.pt and <peg>/opnv.pt), e.g. weights you trained;
DIR is a path or a folder's name in the user folder's agents/cfvs/ (resources.py)."""


def _user_agent(spec: str) -> type[Agent]:
    """`package.module:Class` -> the class, checked to be an Agent built from a TaskSpec."""
    import importlib
    import inspect

    module_name, _, class_name = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except Exception as e:  # ModuleNotFoundError, or the module itself fails to import
        raise KeyError(f"agent '{spec}': cannot import module '{module_name}' ({e})") from e
    cls = getattr(module, class_name, None)
    if cls is None:
        raise KeyError(f"agent '{spec}': module '{module_name}' has no '{class_name}'")
    if not (inspect.isclass(cls) and issubclass(cls, Agent)) or inspect.isabstract(cls):
        raise KeyError(
            f"agent '{spec}': '{class_name}' is not a concrete subclass of "
            "cfvs_maniskill.agents.base.Agent (it needs act(observation))"
        )
    return cls


ENTRY_POINT_GROUP = "cfvs_maniskill.agents"
"""Installed packages can name their agents here (pyproject.toml:
`[project.entry-points."cfvs_maniskill.agents"] mine = "my_pkg.my_module:MyAgent"`), then
`--agent mine` works like a built-in name."""


def installed_agents() -> dict[str, str]:
    """Agent names that installed packages declare in ENTRY_POINT_GROUP -> their
    `package.module:Class`."""
    from importlib.metadata import entry_points

    return {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}


def _user_factory(name: str, spec: str) -> Callable[..., Agent]:
    cls = _user_agent(spec)

    def make(task: TaskSpec) -> Agent:
        agent = cls(task)
        agent.name = name  # records and reports use the name it was asked by
        return agent

    return make


def ablation_names() -> list[str]:
    """`cfvs_<ablation>` for every CFVS ablation, listed in AGENTS or not."""
    from cfvs_maniskill.agents.cfvs import ABLATIONS

    return [f"cfvs_{a}" for a in ABLATIONS]


def resolve_agent(name: str) -> Callable[..., Agent]:
    """The factory for an agent name: a registered one, a CFVS ablation (`cfvs_<key of
    cfvs.ABLATIONS>`), one an installed package declares
    (ENTRY_POINT_GROUP), `cfvs@DIR`, or your own class as `package.module:Class` (built with
    the task's TaskSpec); KeyError with a message naming what is wrong."""
    if name in AGENTS:
        return AGENTS[name]
    if name in ablation_names():
        return _cfvs(name, ablation=name.removeprefix("cfvs_"))
    installed = installed_agents()
    if name in installed:
        return _user_factory(name, installed[name])
    if name.startswith(WEIGHTS_PREFIX):
        from cfvs_maniskill import resources

        spec = name[len(WEIGHTS_PREFIX) :]
        folder = resources.find("agents", spec, "", sub="cfvs")
        if folder is None or not folder.is_dir():
            raise KeyError(
                f"agent '{name}': no weights folder '{spec}' (a path, or a folder name in "
                f"{' or '.join(str(d) for d in resources.search_dirs('agents', 'cfvs'))})"
            )
        return _cfvs(name, weights=str(folder.resolve()))
    if ":" in name:
        return _user_factory(name, name)
    raise KeyError(
        f"unknown agent '{name}'; valid: {', '.join([*AGENTS, *installed])}, the CFVS "
        f"ablations {', '.join(n for n in ablation_names() if n not in AGENTS)}, "
        f"{WEIGHTS_PREFIX}DIR (CFVS with the weights in DIR) or package.module:Class (your "
        "own Agent subclass)"
    )


def agent_env_kwargs(name: str) -> dict:
    """The gym.make keywords the agent `name` needs: its class's ManiSkill obs mode and any
    other env options (`obs_mode`, `env_options`)."""
    resolve_agent(name)  # an unknown name fails here, with the list of valid ones
    spec = BUILTIN_CLASSES.get(name) or installed_agents().get(name)
    if spec is None:
        builtin = name in ablation_names() or name.startswith(WEIGHTS_PREFIX)
        spec = BUILTIN_CLASSES["cfvs"] if builtin else name
    cls = _user_agent(spec)
    return {"obs_mode": cls.obs_mode, **cls.env_options}


def make_agent(name: str, env) -> Agent:
    """The agent `name` for `env`'s task: built from the task's constants alone, except the
    privileged oracle; `agent.weights` says which weights files it loaded (provenance)."""
    from cfvs_maniskill.nets.checkpoint import WeightsError
    from cfvs_maniskill.provenance import track_weights

    factory = resolve_agent(name)
    with track_weights() as loaded:
        try:
            agent = factory(env) if name in PRIVILEGED else factory(TaskSpec.of(env.unwrapped.task))
        except WeightsError:
            raise  # a missing or wrong weights file: the caller names it and stops
        except Exception as e:  # a bug in the agent's constructor fails its episodes
            agent = UnbuiltAgent(AgentFailure.of(name, 0, e))
    agent.weights = loaded
    return agent


class UnbuiltAgent(Agent):
    """Stands in for an agent whose constructor raised: every episode fails with that error
    (recorded, counted as a failure) and the evaluation goes on."""

    def __init__(self, failure: AgentFailure):
        self.name, self.failure = failure.agent, failure

    def reset(self, seed: int) -> None:
        raise self.failure

    def act(self, observation: Observation) -> Action:
        raise self.failure
