"""Rendered videos for the report: the first success and the first failure of each agent
on each task, replayed from the result record (episodes are fixed by their seed, object
and initial error, so a replay in a fresh env shows the recorded episode)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from cfvs_maniskill.constants import DEFAULT_SEARCH_RADIUS


@dataclass
class Video:
    record: dict
    path: Path | None
    """None: the episode could not be replayed (the reason says why)."""
    replay_success: bool
    replay_reason: str

    @property
    def recorded(self) -> str:
        return "success" if self.record["success"] else "failure"


def pick(records: list[dict], variants: bool = False) -> list[dict]:
    """First success and first failure per (task, label, sensor) in file order; with
    `variants` False only of labels that are an agent family's own name (cfvs, 3drhd, ...,
    your own agents) under the ideal sensor, not its ablations, no-search runs or other
    sensor profiles. Variants named only by their
    folder (e.g. results/cfvs_plain from the run command) are always skipped: their
    executor settings are not in the record, so a replay could not match."""
    from cfvs_maniskill.report.style import family

    chosen: dict[tuple, dict] = {}
    # Runner records first: they carry the exact job (object, error, seed) of the episode.
    for r in sorted(records, key=lambda r: "key" not in r):
        if r["label"] != r["agent"] and "search_radius_m" not in r:
            continue
        if not variants and (
            r["label"] != family(r["label"]) or r.get("sensor", "ideal") != "ideal"
        ):
            continue
        sensor = r.get("sensor", "ideal")
        chosen.setdefault((r["task"], r["label"], sensor, bool(r["success"])), r)
    return [chosen[k] for k in sorted(chosen, key=lambda k: (k[0], k[1], k[2], not k[3]))]


def video_name(rec: dict) -> str:
    outcome = "success" if rec["success"] else "failure"
    sensor = rec.get("sensor", "ideal")
    return f"{rec['task']}_{rec['label']}_{outcome}" + ("" if sensor == "ideal" else f"_{sensor}")


IDENTITY = "episode: "


def episode_identity(rec: dict) -> str:
    """What makes a record's episode: its job, seed and the episode code that ran it."""
    code = (rec.get("provenance") or {}).get("code_fingerprint", "")
    return f"{rec.get('key', '')} seed {rec['seed']} code {code}"


def _kept(path: Path, meta: Path, rec: dict) -> tuple[bool, str] | None:
    """(replayed success, reason) of a video already rendered of this very episode; None
    when there is none, or the file is of another episode (another seed, job or code)."""
    if not (path.is_file() and meta.is_file()):
        return None
    first, _, rest = meta.read_text().partition("\n")
    if rest.strip() != IDENTITY + episode_identity(rec):
        return None
    ok, _, reason = first.partition(" ")
    return ok == "success", reason.strip()


def render(
    picks: list[dict],
    out: Path,
    assets: tuple[Path, ...] = (),
    search_radius: float = DEFAULT_SEARCH_RADIUS,
) -> list[Video]:
    """Replay each picked episode, filmed (`rendering/film.py`, as `run --video`), into
    OUT/<name>.mp4; a file already there of the same episode is kept (a second report run
    renders nothing again), one of another episode or code rendered anew."""
    from tqdm import tqdm

    from cfvs_maniskill.envs.lookup import sensor_of_record, task_of_record
    from cfvs_maniskill.policies.registry import agent_env_kwargs
    from cfvs_maniskill.rendering.film import Film
    from cfvs_maniskill.session import make_env, open_session

    out.mkdir(parents=True, exist_ok=True)
    envs: dict[tuple, object] = {}
    objects: dict[str, set[str]] = {}
    for r in picks:
        objects.setdefault(r["task"], set()).add(r["object"])
    videos = []
    for rec in tqdm(picks, desc="videos", unit="video"):
        path = out / f"{video_name(rec)}.mp4"
        meta = path.with_suffix(".txt")
        kept = _kept(path, meta, rec)
        if kept is not None:
            videos.append(Video(rec, path, *kept))
            continue
        sensor = rec.get("sensor", "ideal")
        try:
            key = (rec["task"], tuple(sorted(agent_env_kwargs(rec["agent"]).items())), sensor)
            if key not in envs:
                envs[key] = make_env(
                    task_of_record(rec),
                    rec["agent"],
                    sensor=sensor_of_record(rec),
                    objects=sorted(objects[rec["task"]]),
                    assets=assets,
                )
        except (KeyError, ValueError) as e:  # an agent, task or profile gone since, a bad file
            tqdm.write(f"{path.stem}: not rendered: {e}")
            videos.append(Video(rec, None, False, f"not rendered: {e}"))
            continue
        env = envs[key]
        u = env.unwrapped
        u.init_error_m = u.task.init_error[rec["init"]]
        radius = rec.get("search_radius_m", search_radius)
        film = Film(env, rec["label"])
        try:
            session = open_session(env, rec["agent"], radius)
            r = session.episode(rec["seed"], options={"object": rec["object"]}, film=film)
        except Exception as e:  # e.g. missing weights, an object this env lacks
            tqdm.write(f"{path.stem}: not rendered: {e}")
            videos.append(Video(rec, None, False, f"not rendered: {e}"))
            continue
        film.write(path)
        outcome = "success" if r.success else "failure"
        meta.write_text(f"{outcome} {r.reason}\n{IDENTITY}{episode_identity(rec)}\n")
        videos.append(Video(rec, path, r.success, r.reason))
    for env in envs.values():
        env.close()
    for gone in prune(out, {video_name(r) for r in picks}):
        tqdm.write(f"{gone.name}: removed (no longer among the episodes shown)")
    return videos


FILM_SUFFIXES = (".mp4", ".txt")
"""A video and the note of the episode it shows."""


def prune(out: Path, shown: set[str]) -> list[Path]:
    """Remove the videos in `out` (and their notes) whose name is not in `shown`: films of
    episodes the records no longer pick would sit beside the report as if it showed them."""
    gone = [f for f in sorted(out.iterdir()) if f.suffix in FILM_SUFFIXES and f.stem not in shown]
    for f in gone:
        f.unlink()
    return gone


def markdown(videos: list[Video], base: Path) -> str:
    """A table of links, relative to the report folder `base`."""
    if not videos:
        return "No episodes to show."
    lines = [
        "| task | agent | sensor | recorded | object | seed | video | replayed |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for v in videos:
        r = v.record
        if v.path is None:
            link, replay = "-", v.replay_reason
        else:
            link = f"[{v.path.name}]({v.path.relative_to(base)})"
            replay = "success" if v.replay_success else f"failure ({v.replay_reason})"
        lines.append(
            f"| {r['task']} | {r['label']} | {r.get('sensor', 'ideal')} | {v.recorded} | "
            f"{r['object']} | {r['seed']} | "
            f"{link} | {replay} |"
        )
    return "\n".join(lines)
