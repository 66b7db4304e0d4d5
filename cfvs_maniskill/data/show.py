"""Draw one dataset sample so a person can check its labels (matplotlib, no display needed)."""

from __future__ import annotations

from pathlib import Path

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cfvs_maniskill.data.store import FORMAT, DatasetError  # noqa: E402


def _read(path: Path, index: int) -> tuple[dict, dict]:
    if not path.is_file():
        raise DatasetError(f"{path}: no such dataset file")
    with h5py.File(path, "r") as f:
        attrs = dict(f.attrs)
        if attrs.get("format") != FORMAT:
            raise DatasetError(f"{path}: field 'format': expected {FORMAT}")
        m = len(f["sample_index"])
        if not -m <= index < m:
            raise DatasetError(f"--index: {path} holds {m} samples (0..{m - 1}), got {index}")
        row = {k: (f[k].asstr()[index] if k == "object" else f[k][index]) for k in f}
    return attrs, row


def show(path: Path, index: int, out: Path) -> Path:
    """Write a PNG of sample `index`: 3D view and top view, keypoints and confidence."""
    attrs, row = _read(Path(path), index)
    p = row["points"]
    fig = plt.figure(figsize=(12, 5.5))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    kind = attrs["kind"]
    if kind == "coarse":
        c, k = row["confidence"], row["keypoints"]
        order = np.argsort(c)
        for ax, dims in ((ax3, (0, 1, 2)), (ax2, (0, 1))):
            coords = [p[order, d] for d in dims]
            sc = ax.scatter(*coords, c=c[order], cmap="viridis", s=4, vmin=0, vmax=1)
            for j, (name, col) in enumerate((("k1", "red"), ("k2", "orange"), ("k3", "magenta"))):
                ax.scatter(*[k[j, d] for d in dims], color=col, s=60, marker="*", label=name)
            for j in (1, 2):
                ax.plot(*[[k[0, d], k[j, d]] for d in dims], color="red", lw=2)
        fig.colorbar(sc, ax=ax2, label="confidence target w*")
        title = f"coarse #{index}: {row['object']}, tip {100 * row['init_error']:.0f} cm from hole"
    else:
        a = row["action"]
        for ax, dims in ((ax3, (0, 1, 2)), (ax2, (0, 1))):
            ax.scatter(*[p[:, d] for d in dims], c=p[:, 2], cmap="viridis", s=4)
            ax.scatter(*[[0.0] for _ in dims], color="red", s=60, marker="*", label="peg tip")
            ax.plot(*[[0.0, a[d]] for d in dims], color="red", lw=2, label="action dt")
        dr = np.degrees(np.linalg.norm(a[3:]))
        title = (
            f"fine #{index}: {row['object']}, dt {1000 * np.linalg.norm(a[:3]):.1f} mm, "
            f"dr {dr:.1f} deg"
        )
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z along the peg (m)")
    ax3.view_init(elev=-70, azim=-90)  # looking down the peg, as the camera does
    ax2.set_aspect("equal")
    ax2.invert_yaxis()
    ax2.set_xlabel("x (tool frame, m)")
    ax2.set_ylabel("y (tool frame, m)")
    ax2.legend(loc="upper right", fontsize=8)
    fig.suptitle(f"{title}  [{attrs['task']}, tool frame]")
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
