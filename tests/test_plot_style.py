"""Plot style (`report/style.py`): one colour per agent, variants in their agent's colour
with distinct line styles, at most MAX_LINES lines in a panel."""

from __future__ import annotations

from cfvs_maniskill.report import style

LABELS = [
    "cfvs", "cfvs (realistic)", "cfvs_no_map", "cfvs_no_c2f", "cfvs_aug", "cfvs_plain",
    "cfvs_ideal_data", "cfvs@my_weights", "3drhd", "3drhd_plain", "icp", "icp_kpts",
    "icp_kpts_plain", "kovis", "oracle", "my_pkg.agents:Mine",
]  # fmt: skip


def test_every_agent_family_has_its_own_colour_and_marker():
    look = style.looks(LABELS)
    heads = ["cfvs", "3drhd", "icp", "icp_kpts", "kovis", "oracle", "my_pkg.agents:Mine"]
    assert len({look[h].colour for h in heads}) == len(heads)
    assert len({look[h].marker for h in heads}) == len(heads)
    assert style.family("icp_kpts_plain") == "icp_kpts" and style.family("icp") == "icp"


def test_variants_share_their_agents_colour_and_differ_in_line_style():
    look = style.looks(LABELS)
    variants = [lb for lb in LABELS if style.family(lb) == "cfvs"]
    assert {look[lb].colour for lb in variants} == {look["cfvs"].colour}
    assert look["cfvs"].linestyle == "-"  # the agent itself: solid


def test_panels_hold_at_most_six_lines_with_distinct_styles_and_show_every_label():
    panels = style.panels(LABELS)
    assert all(0 < len(group) <= style.MAX_LINES for _, group in panels)
    assert {lb for _, group in panels for lb in group} == set(LABELS)
    first = panels[0][1]  # the agents side by side
    assert first[0] == "cfvs" and "3drhd" in first and "kovis" in first
    for _, group in panels:
        look = style.looks(group)
        pairs = [(look[lb].colour, str(look[lb].linestyle)) for lb in group]
        assert len(set(pairs)) == len(group)  # no two lines look the same
