"""One look for every plot: a colour and a marker per agent family (CFVS, each baseline,
the oracle, then anyone's own agents), its variants (ablations, other weights, no search,
another sensor) in line styles / hatches of that colour, so that a reader can follow an
agent from plot to plot."""

from __future__ import annotations

from dataclasses import dataclass

FAMILIES = ("cfvs", "3drhd", "icp_kpts", "icp", "kovis", "oracle")
"""Known agent families, longest prefix first (icp_kpts before icp)."""
COLOURS = ("#1f5fbf", "#e07b00", "#2a9d3a", "#c0392b", "#8e44ad", "#555555")
"""Okabe-Ito-like, distinct in print and for the common colour-vision deficiencies."""
EXTRA_COLOURS = ("#17becf", "#bcbd22", "#e377c2", "#8c564b", "#7f7f7f")
"""For families the project does not know (your own agents), in order of appearance."""
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "h", "<", ">")
LINESTYLES = ("-", "--", ":", "-.", (0, (5, 1, 1, 1, 1, 1)), (0, (1, 3)))
HATCHES = ("", "//", "..", "xx", "\\\\", "--")
MAX_LINES = 6
"""Most lines (or bar groups) drawn in one panel: more split into further panels."""


def family(label: str) -> str:
    """The agent family of a plot label: `cfvs_no_map` -> cfvs, `icp_kpts_plain` ->
    icp_kpts, `cfvs@w (realistic)` -> cfvs, `my_pkg.mod:Agent` -> itself."""
    base = label.split(" ")[0]
    for f in FAMILIES:
        if base == f or base.startswith((f + "_", f + "@")):
            return f
    return base


@dataclass(frozen=True)
class Look:
    colour: str
    marker: str
    linestyle: object
    hatch: str


def looks(labels: list[str]) -> dict[str, Look]:
    """A look per label: its family's colour and marker, and for the family's k-th label (the
    bare family name first) the k-th line style and hatch."""
    fams = sorted({family(lb) for lb in labels}, key=_family_order)
    colour, marker = {}, {}
    extra = 0
    for f in fams:
        if f in FAMILIES:
            colour[f] = COLOURS[FAMILIES.index(f)]
            marker[f] = MARKERS[FAMILIES.index(f)]
        else:
            colour[f] = EXTRA_COLOURS[extra % len(EXTRA_COLOURS)]
            marker[f] = MARKERS[(len(FAMILIES) + extra) % len(MARKERS)]
            extra += 1
    out = {}
    for f in fams:
        members = sorted((lb for lb in labels if family(lb) == f), key=lambda lb: (lb != f, lb))
        for k, lb in enumerate(members):
            out[lb] = Look(
                colour[f], marker[f], LINESTYLES[k % len(LINESTYLES)], HATCHES[k % len(HATCHES)]
            )
    return out


def _family_order(f: str) -> tuple[int, str]:
    return (FAMILIES.index(f) if f in FAMILIES else len(FAMILIES), f)


def panels(labels: list[str]) -> list[tuple[str, list[str]]]:
    """Labels split into panels of at most MAX_LINES: first the families' own agents side
    by side (CFVS against the baselines), then each family's variants."""
    labels = sorted(set(labels), key=lambda lb: (_family_order(family(lb)), lb))
    heads = [lb for lb in labels if lb == family(lb)]
    rest = [lb for lb in labels if lb not in heads]
    out = []
    for i in range(0, len(heads), MAX_LINES):
        out.append(("agents", heads[i : i + MAX_LINES]))
    for f in dict.fromkeys(family(lb) for lb in rest):
        body = [lb for lb in rest if family(lb) == f]
        lead = [f] if f in heads else []  # the variants beside the agent itself
        step = MAX_LINES - len(lead)
        for i in range(0, len(body), step):
            out.append((f"{f} variants", lead + body[i : i + step]))
    return out


def order(labels: list[str]) -> list[str]:
    """Every label once, in panel order: the families' own agents, then each family's
    variants (for plots that show all labels in one axis)."""
    return list(dict.fromkeys(lb for _, group in panels(labels) for lb in group))
