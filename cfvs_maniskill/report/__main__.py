"""`python -m cfvs_maniskill.report DIR --out report/`: the paper's tables and plots from
every result file (*.jsonl) below DIR: evaluation runs and run-command files alike."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro


@dataclass
class ReportArgs:
    """Write REPORT/README.md (Tables II-IV beside the paper's) and PNG plots."""

    results: Annotated[Path, tyro.conf.Positional]
    """Folder searched recursively for *.jsonl result files."""
    out: Path = Path("report")
    """Output folder."""
    videos: bool = True
    """Render the first success and first failure per agent and task into OUT/videos
    (replayed from their records; a file of the same episode is kept)."""
    video_variants: bool = False
    """Also film the variants (ablations, other weights, no-search runs, other sensor
    profiles); by default each agent's own records under the ideal sensor only (a video costs about
    10-30 s of rendering on 2 CPU cores: docs/videos.md)."""
    assets: tuple[Path, ...] = ()
    """Extra hole-object folders or files the results used: their records are reported
    (without, records on objects outside the default library are left out) and replayed."""
    readme: Path | None = None
    """Also fill the headline tables (main agents, tasks and sensor profiles, 15 / 30 cm)
    into this file between its `<!-- report:headline begin/end -->` markers (and, where it
    has them, `report:headline-cameras`: the d435 and textured profiles)."""
    check: bool = False
    """Write nothing; exit 1 when a headline cell comes from mixed, stale or crashed records
    (report/trace.py) or when --readme's headline tables are not what the records give."""


def check(records: list[dict], crashed: list[dict], readme: Path | None) -> int:
    """`--check`: every headline cell current and of one provenance, the README's table
    what the records give. Prints a line per headline table naming the code that made it,
    then each problem; 0 when there is none."""
    from cfvs_maniskill.report import tables, trace

    cells = tables.headline_cells(records + crashed)
    today = trace.code_fingerprint()
    for table, sensors in tables.HEADLINES.items():
        recs = [r for (_, _, sensor, _), rs in cells.items() if sensor in sensors for r in rs]
        if recs:
            current = all(trace.code_current(r, trace.resolve(r)) for r in recs)
            state = "today's episode code" if current else "NOT today's episode code"
            print(
                f"table {table} ({', '.join(sensors)}): {len(recs)} records, code "
                f"{trace.code_versions(recs)}: {state} ({today})"
            )
    problems = []
    for (label, task, sensor, init), recs in cells.items():
        status, reasons = trace.cell_status(recs)
        if status != "ok":
            problems.append(f"{label} {task} {sensor} {init}: {status}: {'; '.join(reasons)}")
    if readme is not None:
        text = readme.read_text()
        if tables.fill_headlines(text, records, str(readme)) != text:
            problems.append(f"{readme}: the headline tables are not what the records give")
    for p in problems:
        print(p)
    n = len(tables.headline_cells(records))
    print(f"report --check: {len(problems)} problems in {n} headline cells")
    return 1 if problems else 0


def main(args: ReportArgs) -> int:
    from cfvs_maniskill.report import plots, residuals, style, tables, videos
    from cfvs_maniskill.report.load import ReportError, load_records

    if not args.results.is_dir():
        print(f"error: {args.results}: not a folder of results", file=sys.stderr)
        return 2
    crashed: list[dict] = []
    try:
        records = load_records(args.results, crashed, args.assets)
    except FileNotFoundError as e:  # an --assets folder that is not there
        print(f"error: --assets: {e}", file=sys.stderr)
        return 2
    except ReportError as e:  # before anything is written
        print(f"error: {e}", file=sys.stderr)
        return 2
    if not records:
        print(
            f"error: {args.results}: no result records (*.jsonl) on known hole objects found "
            "(records on your own objects need --assets DIR)",
            file=sys.stderr,
        )
        return 2
    if args.check:
        return check(records, crashed, args.readme)
    readme_text = None
    if args.readme is not None:
        try:
            readme_text = tables.fill_headlines(args.readme.read_text(), records, str(args.readme))
        except (OSError, ValueError) as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
    args.out.mkdir(parents=True, exist_ok=True)
    main_recs, variant_recs = plots.heads(records), plots.variants(records)
    pngs = [  # one figure per question, the paper's comparison first
        plots.success_vs_tilt(main_recs or records, args.out),
        plots.success_per_agent(main_recs or records, args.out),
        plots.servo_times(main_recs or records, args.out),
    ]
    residual_png = residuals.plot(records, args.out)
    if residual_png is not None:
        pngs.append(residual_png)
    variant_pngs = []
    if main_recs and variant_recs:  # each variant beside its own agent
        family = {style.family(r["label"]) for r in variant_recs}
        beside = [r for r in main_recs if r["label"] in family] + variant_recs
        variant_pngs = [
            plots.success_vs_tilt(beside, args.out, name="variants_success_vs_tilt"),
            plots.success_per_agent(beside, args.out, name="variants_success"),
        ]
    if args.videos:
        picks = videos.pick(records, variants=args.video_variants)
        shown = videos.render(picks, args.out / "videos", args.assets)
        video_md = videos.markdown(shown, args.out)
    else:
        video_md = "Not rendered (`--no-videos`)."
    ideal = [r for r in records if r["sensor"] == "ideal"]  # the paper's protocol
    text = "\n\n".join(
        [
            f"# Report: {args.results} ({len(records)} episodes)",
            "## Table II: success, ideal sensor (averages over all objects in the results, then "
            "per object: the paper's four, or those of the results)",
            tables.table_ii(ideal),
            "## Success per sensor profile (sensors/*.yaml)",
            tables.table_sensors(records),
            "## Table III: 3-DoF visual servoing time (simulated, successes, ideal sensor)",
            tables.table_iii(ideal),
            "## Table IV: ablation (6-DoF, ideal sensor, the paper's protocol: no compliant search)",
            tables.table_iv(ideal),
            "## Closed-loop residual: true error from the pre-insertion pose after each move",
            residuals.table(records),
            "## Episodes ended by an agent's own error",
            tables.table_agent_errors(records),
            "## Provenance: which code and files each agent's records come from",
            tables.table_provenance(records, crashed),
            "## Plots: the agents (CFVS, the paper's baselines, the oracle)",
            "\n".join(f"![{p.stem}]({p.name})" for p in pngs),
            "## Plots: variants (ablations, other weights or settings) beside their agent",
            "\n".join(f"![{p.stem}]({p.name})" for p in variant_pngs) or "No variants here.",
            "## Videos: first success and first failure per agent and task",
            video_md,
        ]
    )
    summary = (
        f"# Success per agent, task and sensor profile ({len(records)} episodes)\n\n"
        + tables.table_compact(records)
        + "\n"
    )
    for name, content in (("summary.md", summary), ("README.md", text + "\n")):
        tmp = args.out / f".{name}.tmp"  # whole or not at all: a reader never sees half
        tmp.write_text(content)
        tmp.replace(args.out / name)
    if readme_text is not None:
        args.readme.write_text(readme_text)
        print(f"filled the headline tables into {args.readme}")
    print(f"wrote {args.out / 'README.md'} and {len(pngs)} plots ({len(records)} episodes)")
    return 0


if __name__ == "__main__":
    sys.exit(main(tyro.cli(ReportArgs)))
