"""A projected density map of one epoch from a query, with matplotlib.

    python3 density_projection.py STORE [EPOCH] [OUTPUT.png]

Reads the points of a coarse level of detail (each carries the mass it
stands for, so the map has the mass of all particles), bins them along z
and writes a log-scaled image.
"""
import sys

import matplotlib

matplotlib.use("Agg")  # no display needed
import matplotlib.pyplot as plt
import numpy as np

import octocosm

store = octocosm.open(sys.argv[1])
epoch = int(sys.argv[2]) if len(sys.argv) > 2 else store.epochs - 1
output = sys.argv[3] if len(sys.argv) > 3 else "density.png"

info = store.info()["epochs"][epoch]
points = store.query(epoch=epoch, level=4, columns=["weight"])
x, y = points["position"][:, 0], points["position"][:, 1]
origin, size = info["cube_origin"], info["cube_size"]
edges = [np.linspace(origin[0], origin[0] + size, 257), np.linspace(origin[1], origin[1] + size, 257)]
mass, _, _ = np.histogram2d(x, y, bins=edges, weights=points["weight"])
print(f"epoch {epoch} (z = {info['redshift']:.2f}): {len(x)} points, mass {mass.sum():.6g} "
      f"of {info['mass']:.6g}")

plt.figure(figsize=(6, 6))
plt.imshow(np.log10(mass.T + mass[mass > 0].min()), origin="lower", cmap="magma",
           extent=(origin[0], origin[0] + size, origin[1], origin[1] + size))
plt.xlabel("x")
plt.ylabel("y")
plt.title(f"projected mass, z = {info['redshift']:.2f}")
plt.colorbar(label="log10 mass per pixel")
plt.savefig(output, dpi=100)
