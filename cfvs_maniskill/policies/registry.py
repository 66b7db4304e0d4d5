"""Agent names for `--agent`, each a factory taking the task's nominal constants (TaskSpec).

Only the oracle's factory takes the env (it reads true poses: the ceiling, not an agent a
robot could run); `make_agent` hands the env to nothing else."""

from __future__ import annotations

import importlib
from collections.abc import Callable

from cfvs_maniskill.policies.base import Action, Agent, AgentEntry, AgentFailure, Observation
from cfvs_maniskill.policies.interface import TaskSpec

POLICIES = ("cfvs", "icp", "hole_detect", "kovis", "oracle")
"""The policy folders. Each names its agents in `AGENTS` (name -> AgentEntry) and may take
more names in `resolve(name)` (CFVS: its ablations and weights folders); importing them
is light (the agent, its networks and torch load when an agent is built)."""


def _policy(folder: str):
    return importlib.import_module(f"{__package__}.{folder}")


AGENTS: dict[str, AgentEntry] = {
    name: e for folder in POLICIES for name, e in _policy(folder).AGENTS.items()
}
"""Every listed agent name -> its entry: the paper's agent and ablations, its baselines
(Table II: icp, icp_kpts, 3drhd, kovis) and the oracle."""
DEFAULT_AGENT = "cfvs"
PRIVILEGED = {name for name, e in AGENTS.items() if e.privileged}
"""Agents that take the env itself (they read the truth)."""


def _user_agent(spec: str) -> type[Agent]:
    """`package.module:Class` -> the class, checked to be an Agent built from a TaskSpec."""
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
            "cfvs_maniskill.policies.base.Agent (it needs act(observation))"
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


def _entry(name: str) -> AgentEntry:
    """The entry for an agent name: a listed one, one a policy folder resolves (CFVS's
    ablations `cfvs_<key>` and `cfvs@DIR`), one an installed package declares
    (ENTRY_POINT_GROUP), or your own class as `package.module:Class` (built with the task's
    TaskSpec); KeyError with a message naming what is wrong."""
    if name in AGENTS:
        return AGENTS[name]
    for folder in POLICIES:
        resolve = getattr(_policy(folder), "resolve", None)
        if resolve is not None and (found := resolve(name)) is not None:
            return found
    installed = installed_agents()
    if name in installed or ":" in name:
        spec = installed.get(name, name)
        return AgentEntry(spec, _user_factory(name, spec))
    more = [h for h in (getattr(_policy(f), "HELP", "") for f in POLICIES) if h]
    raise KeyError(
        f"unknown agent '{name}'; valid: {', '.join([*AGENTS, *installed])}, "
        f"{', '.join(more)} or package.module:Class (your own Agent subclass)"
    )


def resolve_agent(name: str) -> Callable[..., Agent]:
    """The factory for an agent name (`_entry` says which names there are)."""
    return _entry(name).make


def agent_env_kwargs(name: str) -> dict:
    """The gym.make keywords the agent `name` needs: its class's ManiSkill obs mode and any
    other env options (`obs_mode`, `env_options`)."""
    cls = _user_agent(_entry(name).cls)
    return {"obs_mode": cls.obs_mode, **cls.env_options}


def make_agent(name: str, env) -> Agent:
    """The agent `name` for `env`'s task: built from the task's constants alone, except the
    privileged oracle; `agent.weights` says which weights files it loaded (provenance)."""
    from cfvs_maniskill.nets.checkpoint import WeightsError
    from cfvs_maniskill.provenance import track_weights

    entry = _entry(name)
    factory = entry.make
    with track_weights() as loaded:
        try:
            agent = factory(env) if entry.privileged else factory(TaskSpec.of_env(env))
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
