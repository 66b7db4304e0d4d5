"""The paper's numbers (Tables II-IV), to print beside ours."""

from __future__ import annotations

OBJECTS = ("cuboid_test_1", "cuboid_test_2", "cylinder", "pentagonal_prism")
"""Our names of the paper's four unseen objects (Cuboid_1, Cuboid_2, Cylinder, Pentagonal prism)."""

# Table II: (average, per object in OBJECTS order), each (15 cm, 30 cm).
TABLE_II: dict[int, dict[str, tuple]] = {
    3: {
        "icp": ((0.10, 0.10), (0.11, 0.10), (0.10, 0.11), (0.11, 0.11), (0.07, 0.08)),
        "icp_kpts": ((0.67, 0.69), (0.71, 0.74), (0.77, 0.76), (0.69, 0.70), (0.52, 0.54)),
        "3drhd": ((0.69, 0.68), (0.80, 0.79), (0.73, 0.71), (0.63, 0.62), (0.61, 0.61)),
        "kovis": ((0.95, 0.80), (1.00, 0.88), (1.00, 0.87), (0.86, 0.71), (0.94, 0.75)),
        "cfvs": ((1.00, 1.00), (1.00, 1.00), (1.00, 1.00), (1.00, 1.00), (1.00, 1.00)),
    },
    4: {
        "icp": ((0.00, 0.00),) * 5,
        "icp_kpts": ((0.23, 0.22), (0.55, 0.56), (0.26, 0.25), (0.01, 0.00), (0.08, 0.07)),
        "3drhd": ((0.02, 0.01), (0.03, 0.02), (0.01, 0.00), (0.00, 0.00), (0.02, 0.02)),
        "kovis": ((0.16, 0.02), (0.18, 0.03), (0.26, 0.03), (0.06, 0.01), (0.12, 0.02)),
        "cfvs": ((0.92, 0.91), (0.98, 0.97), (0.98, 1.00), (0.78, 0.76), (0.92, 0.89)),
    },
    6: {
        "icp": ((0.00, 0.00),) * 5,
        "icp_kpts": ((0.21, 0.20), (0.64, 0.63), (0.08, 0.07), (0.05, 0.03), (0.05, 0.06)),
        "3drhd": ((0.00, 0.00),) * 5,
        "kovis": ((0.02, 0.02), (0.04, 0.03), (0.03, 0.03), (0.01, 0.00), (0.00, 0.00)),
        "cfvs": ((0.82, 0.82), (0.92, 0.93), (0.90, 0.94), (0.76, 0.72), (0.70, 0.69)),
    },
}
TABLE_III = {"kovis": (6.6, 10.1), "cfvs": (7.0, 7.1)}
"""3-DoF visual servoing time, seconds, 15 / 30 cm."""
TABLE_IV = {
    "cfvs_no_c2f": 0.51,
    "cfvs_no_map": 0.73,
    "cfvs_no_aug": 0.77,
    "cfvs_aug": 0.82,  # the paper's full model is trained with augmentation
    "cfvs": 0.82,  # ours as shipped (square nets trained without it, see agents/cfvs)
}
"""6-DoF ablation, success averaged over the four unseen objects (rows b, c, d, e)."""
