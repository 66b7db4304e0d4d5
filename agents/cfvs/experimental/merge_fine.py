"""One-off (session 9): interleave two fine datasets into one file for `train`."""

import h5py
import numpy as np

SOURCES = ("/tmp/exp/fine_realistic.h5", "/tmp/exp/fine_ideal.h5")
OUT = "/tmp/exp/fine_mixed.h5"

a, b = (h5py.File(p, "r") for p in SOURCES)
n = min(len(a["action"]), len(b["action"]))
with h5py.File(OUT, "w") as out:
    for k, v in a.attrs.items():
        out.attrs[k] = v
    for k in a:
        x, y = a[k][:n], b[k][:n]
        z = np.empty((2 * n, *x.shape[1:]), dtype=x.dtype)
        z[0::2], z[1::2] = x, y  # interleaved: the held-out tail has both sensors
        out.create_dataset(k, data=z.astype("S") if x.dtype == object else z)
print("merged", 2 * n)
