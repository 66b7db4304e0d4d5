"""Agent names for `--agent`, each a factory taking the task's nominal constants (TaskSpec).

Only the oracle's factory takes the env (it reads true poses: the ceiling, not an agent a
robot could run); `make_agent` hands the env to nothing else."""

from __future__ import annotations

from collections.abc import Callable

from cfvs_maniskill.agents.base import Agent
from cfvs_maniskill.agents.interface import TaskSpec


def _oracle(env) -> Agent:
    from cfvs_maniskill.agents.oracle import OracleAgent

    return OracleAgent(env)


def _cfvs(name: str = "cfvs", weights: str = "", **switches) -> Callable[..., Agent]:
    """CFVS with config `switches`; `weights`: a weights folder (its tasks.yaml says which
    files), bundled under agents/cfvs/ or an absolute path, instead of the shipped default."""

    def make(task: TaskSpec) -> Agent:
        from cfvs_maniskill.agents.cfvs import WEIGHTS_DIR, CFVSAgent, CFVSConfig

        cfg = dict(switches)
        if weights:
            cfg["weights_dir"] = WEIGHTS_DIR / weights  # an absolute path stays itself
        agent = CFVSAgent(task, CFVSConfig(**cfg))
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


EARLIER_FINE_LOOP = {"tol_translation": 0.0015, "vote_gate": 0.0, "final_correction": False}
"""The fine loop before e_t 1.0 mm, the single-vote steps and the final correction: the
comparison variants keep it, so their committed records stay what the code does."""

BEFORE_FACE_HEIGHT = {"face_height": False, "face_guard": False}
"""OPN's height for the opening instead of the face's: the comparison variants keep it, so
their committed records stay what the code does; `cfvs_opn_height` is the agent they
compare with (docs/results.md has their history)."""

AGENTS: dict[str, Callable[..., Agent]] = {
    "cfvs": _cfvs(),
    # The paper's ablations (Table IV).
    "cfvs_no_c2f": _cfvs("cfvs_no_c2f", coarse_to_fine=False, **BEFORE_FACE_HEIGHT),
    "cfvs_no_map": _cfvs("cfvs_no_map", confidence_map=False, **BEFORE_FACE_HEIGHT),
    "cfvs_no_aug": _cfvs("cfvs_no_aug", augmentation=False, **BEFORE_FACE_HEIGHT),
    # The paper's full model (with its augmentation), as measured: the fine loop of then.
    "cfvs_aug": _cfvs("cfvs_aug", augmentation=True, rim_plane=False, **EARLIER_FINE_LOOP),
    # The fine stage as the paper has it: OPN's own tilt, not the face around the opening.
    "cfvs_no_rim": _cfvs("cfvs_no_rim", rim_plane=False),
    # The opening's height as OPN gives it, not the face's.
    "cfvs_opn_height": _cfvs("cfvs_opn_height", **BEFORE_FACE_HEIGHT),
    # Every fine estimate taken, with or without a face round it.
    "cfvs_no_face_guard": _cfvs("cfvs_no_face_guard", face_guard=False),
    # The estimate's position and yaw as OPN gives them, without the opening fit.
    "cfvs_no_opening": _cfvs("cfvs_no_opening", opening_fit=False, **BEFORE_FACE_HEIGHT),
    # Always the approach yaw nearest the tool's, whatever stands between the camera and
    # the opening.
    "cfvs_fixed_yaw": _cfvs("cfvs_fixed_yaw", clear_view=False, **BEFORE_FACE_HEIGHT),
    # The rim fit on the 20 mm ring always, never the narrow one first.
    "cfvs_wide_ring": _cfvs("cfvs_wide_ring", rim_narrow_ring=False, **BEFORE_FACE_HEIGHT),
    # The face's plane by least median of squares alone, without the parallel-planes check.
    "cfvs_no_parallel": _cfvs("cfvs_no_parallel", rim_parallel_planes=False, **BEFORE_FACE_HEIGHT),
    # The networks before the sensor-mixed OPN and the part-trained OAKN (the fine stage
    # trained on the ideal sensor's clouds only, the coarse one on plain bodies), with the
    # fine loop's stop of then (e_t 1.5 mm): what training on the sensors' noise and on
    # part-like bodies buys.
    "cfvs_ideal_data": _cfvs(
        "cfvs_ideal_data", weights="ideal_data", rim_plane=False, **EARLIER_FINE_LOOP
    ),
    # The coarse network before it was trained on part-like bodies (agents/cfvs/README.md).
    "cfvs_oakn_plain": _cfvs("cfvs_oakn_plain", weights="oakn_plain", **BEFORE_FACE_HEIGHT),
    # The paper's baselines (Table II).
    "icp": _icp("workspace"),
    "icp_kpts": _icp("oakn"),
    "3drhd": _hole_detect,
    "kovis": _kovis,
    "oracle": _oracle,
}
AGENT_ENV = {"oracle": {"obs_mode": "state"}, "kovis": {"obs_mode": "rgbd", "stereo": True}}
"""The env options (gym.make keywords) a built-in agent needs; agents not listed here see
the wrist point cloud (`{"obs_mode": "pointcloud"}`)."""
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


def resolve_agent(name: str) -> Callable[..., Agent]:
    """The factory for an agent name: a registered one, one an installed package declares
    (ENTRY_POINT_GROUP), `cfvs@DIR`, or your own class as `package.module:Class` (built with
    the task's TaskSpec); KeyError with a message naming what is wrong."""
    if name in AGENTS:
        return AGENTS[name]
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
        f"unknown agent '{name}'; valid: {', '.join([*AGENTS, *installed])}, "
        f"{WEIGHTS_PREFIX}DIR (CFVS with the weights in DIR) or package.module:Class (your "
        "own Agent subclass)"
    )


def agent_env_kwargs(name: str) -> dict:
    """The gym.make keywords the agent `name` needs: its ManiSkill obs mode and any other
    env options (an Agent class's `obs_mode` and `env_options`)."""
    if name in AGENT_ENV:
        return dict(AGENT_ENV[name])
    installed = installed_agents()
    spec = installed.get(name) or (
        name if ":" in name and not name.startswith(WEIGHTS_PREFIX) else None
    )
    if spec is None:
        return {"obs_mode": "pointcloud"}
    cls = _user_agent(spec)
    return {"obs_mode": cls.obs_mode, **cls.env_options}


def make_agent(name: str, env) -> Agent:
    """The agent `name` for `env`'s task: built from the task's constants alone, except the
    privileged oracle; `agent.weights` says which weights files it loaded (provenance)."""
    from cfvs_maniskill.provenance import track_weights

    factory = resolve_agent(name)
    with track_weights() as loaded:
        agent = factory(env) if name in PRIVILEGED else factory(TaskSpec.of(env.unwrapped.task))
    agent.weights = loaded
    return agent
