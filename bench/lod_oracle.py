#!/usr/bin/env python3
"""What a level of detail cut for one view could reach: an oracle.

The store's levels of detail are built once for every view, and its frontier
refines a node whole. This script takes every particle the view's full-detail
frame draws (the store's leaves: positions, masses and the smoothing lengths
the reference uses), builds a binary tree over them down to single particles,
and cuts it for the view cell by cell, with one threshold over the whole
picture, on the priority index/aggregator.h orders a node's cells by, measured
on the screen: M (s^2 + w) / (s^2 + v + p^2), with s^2 the members' spread in
pixels, w the spread of their blobs' widths, v their blobs' mean variance and
p half a pixel. Each cell of the cut is drawn as one round blob on the ray
through its members' screen centroid at their mean depth, with the radius
whose kernel variance is their spread plus their blobs' mean variance
(moment matching).

The tree (--grouping): "screen" cuts cells on the screen, across the widest of
x, y and the blob's width in pixels, so that particles one behind the other
merge (a tree for this camera only); "world" cuts them in space, across the
widest of x, y, z and the blob's width, as a tree built once for every view
would be, so that only the cut depends on the view. --levels-per-step 3 lets
a cut stop only at every third level, so that a cell refines into about eight,
as an octree level's clusters would refine into the next level's points.

For each count asked for, the cut with that many points is written as a
GADGET-2 snapshot with its own smoothing lengths (HSML), rendered with
`octocosm render --reference` at the view, and compared with the reference
picture on the grey log scale of bench/error_map.py (PSNR, 1.4-1.6 dB above
the bench's, taken on the colour map). Frames the bench saved
(--save-pictures) are measured on the same scale. docs/ACCURACY.md section 6
has the figures.

  PYTHONPATH=build/python python3 bench/lod_oracle.py --store DIR/store-clusters --reference DIR/reference-mid.pfm \\
      --view "$(grep '^mid:' bench.log | cut -d' ' -f2-)" --full-detail N --counts 0.02,0.05,0.1 \\
      --grouping world --levels-per-step 1,3 --work /tmp/oracle [DIR/picture-mid-clusters-t16-b0.pfm ...]
"""
import argparse
import math
import os
import shlex
import struct
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import error_map  # noqa: E402  (read_pfm, the grey tone map)

try:
    import octocosm
except ImportError:
    octocosm = None

MIN_RADIUS, MAX_RADIUS = 1.0, 127.0  # render/splat_kernel.h
PIXEL = 0.5  # p of the priority, in pixels


# Per-axis variance of the 2-D M4 kernel of radius 1 (render/splat_kernel.h;
# index/aggregator.h's kKernelVariancePerH2).
KERNEL_VARIANCE = 31.0 / 392.0


def parse_view(text):
    flags = shlex.split(text)
    view = {"fov": 60.0}
    for name, value in zip(flags[::2], flags[1::2]):
        key = name.lstrip("-").replace("-", "_")
        try:
            view[key] = [float(x) for x in value.split(",")] if "," in value else float(value)
        except ValueError:
            sys.exit(f"--view: {name} {value}: not a number or a list of numbers")
    for key in ("camera", "look_at", "near", "far"):
        if key not in view:
            sys.exit(f"--view: {key} missing (give the bench's line for the view)")
    return view, flags


def camera_basis(view):
    position = np.array(view["camera"])
    forward = np.array(view["look_at"]) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return position, forward, right, up


def reaches_view(positions, smoothing, view, width, height):
    """Which points' blobs reach into the view (as project() keeps them)."""
    position, forward, right, up = camera_basis(view)
    focal = 0.5 * height / math.tan(math.radians(view["fov"]) / 2)
    d = positions - position
    depth = d @ forward
    front = depth > view["near"]
    safe = np.where(front, depth, 1.0)
    u = 0.5 * width + focal * (d @ right) / safe
    v = 0.5 * height - focal * (d @ up) / safe
    radius = np.clip(smoothing * focal / safe, MIN_RADIUS, MAX_RADIUS)
    return front & (u > -radius) & (u < width + radius) & (v > -radius) & (v < height + radius)


def project(points, view, width, height):
    position, forward, right, up = camera_basis(view)
    focal = 0.5 * height / math.tan(math.radians(view["fov"]) / 2)
    d = points["position"] - position
    depth = d @ forward
    keep = depth > view["near"]
    d, depth = d[keep], depth[keep]
    u = 0.5 * width + focal * (d @ right) / depth
    v = 0.5 * height - focal * (d @ up) / depth
    radius = np.clip(points["smoothing"][keep] * focal / depth, MIN_RADIUS, MAX_RADIUS)
    inside = (u > -radius) & (u < width + radius) & (v > -radius) & (v < height + radius)
    return {
        "u": u[inside], "v": v[inside], "z": depth[inside], "radius": radius[inside],
        "mass": points["weight"][keep][inside], "focal": focal,
        "world": points["position"][keep][inside], "smoothing": points["smoothing"][keep][inside],
    }


def build_tree(p, k, grouping, priority_from):
    """The k-d tree down to single particles: per node its parent, priority and moments on the screen.

    grouping "screen" cuts cells on the screen (u, v and the blob's width in
    pixels); "world" cuts them in space (x, y, z and the blob's width in
    length units), as a tree built once for every view would, and only the
    priorities and the drawn blobs come from the view.
    """
    m, u, v, z = p["mass"], p["u"], p["v"], p["z"]
    blob = k * p["radius"] ** 2
    width_px = np.sqrt(blob)
    # Where cells are cut, besides the screen moments every grouping measures.
    space = [p["world"][:, 0], p["world"][:, 1], p["world"][:, 2], math.sqrt(k) * p["smoothing"]]
    label = np.zeros(m.size, dtype=np.int64)
    members = np.arange(m.size)
    cells = 1  # of the current level
    nodes = {key: [] for key in ("parent", "mass", "u", "v", "z", "spread", "blob", "priority", "terminal")}
    parents_next = np.array([-1])
    next_id = 0
    depth = 0
    while members.size:
        w = m[members]
        mass = np.bincount(label, w, cells)
        safe = np.maximum(mass, 1e-300)

        def mean_and_variance(values):
            mean = np.bincount(label, w * values, cells) / safe
            offset = values - mean[label]
            return mean, offset, np.bincount(label, w * offset * offset, cells) / safe

        mu, offset_u, var_u = mean_and_variance(u[members])
        mv, offset_v, var_v = mean_and_variance(v[members])
        _, offset_width, var_width = mean_and_variance(width_px[members])
        mz = np.bincount(label, w * z[members], cells) / safe
        mean_blob = np.bincount(label, w * blob[members], cells) / safe
        count = np.bincount(label, minlength=cells)
        spread = 0.5 * (var_u + var_v)
        if priority_from == "split":
            priority = mass * (spread + var_width) / (spread + mean_blob + PIXEL**2)
        else:  # what a drawn cluster carries: its mass and its blob's whole variance
            priority = mass * (spread + mean_blob) / (spread + mean_blob + PIXEL**2)
        if grouping == "screen":
            cut_offsets, cut_variances = [offset_u, offset_v, offset_width], [var_u, var_v, var_width]
        else:
            cut_offsets, cut_variances = [], []
            for values in space:
                _, offset, variance = mean_and_variance(values[members])
                cut_offsets.append(offset)
                cut_variances.append(variance)
        cut_variances = np.stack(cut_variances)
        terminal = (count <= 1) | (cut_variances.max(axis=0) <= 0) | (depth >= 80)
        ids = np.arange(next_id, next_id + cells)
        next_id += cells
        for key, value in (("parent", parents_next), ("mass", mass), ("u", mu), ("v", mv), ("z", mz),
                           ("spread", spread), ("blob", mean_blob), ("priority", priority), ("terminal", terminal)):
            nodes[key].append(value)
        # Cut every cell that is not terminal across its widest coordinate at its mean.
        go = ~terminal[label]
        axis = np.argmax(cut_variances, axis=0)[label[go]]
        side = np.choose(axis, [offset[go] > 0 for offset in cut_offsets]).astype(np.int64)
        members, label = members[go], label[go]
        # The widest coordinate varies, so neither side is empty.
        child = label * 2 + side
        unique, label = np.unique(child, return_inverse=True)
        parents_next = ids[unique // 2]
        cells = unique.size
        depth += 1
    tree = {key: np.concatenate(value) for key, value in nodes.items()}
    tree["depth"] = np.concatenate([np.full(len(level), d) for d, level in enumerate(nodes["mass"])])
    tree["level_sizes"] = [len(level) for level in nodes["mass"]]
    return tree


def allow_stops(tree, levels_per_step):
    """Lets a cut stop only every `levels_per_step` levels (and at terminal
    nodes): 3 makes a cell's refinement its about eight grandchildren, as an
    octree level's clusters refine into the next level's points."""
    tree["stop"] = (tree["depth"] % levels_per_step == 0) | tree["terminal"]
    # The smallest priority among each node's ancestors where a cut may stop,
    # level by level (a level's nodes follow the level above's).
    ancestors_min = np.full(tree["mass"].size, np.inf)
    start = 0
    for size in tree["level_sizes"]:
        sel = np.arange(start, start + size)
        parent = tree["parent"][sel]
        has = parent >= 0
        parent = parent[has]
        own = np.where(tree["stop"][parent], tree["priority"][parent], np.inf)
        ancestors_min[sel[has]] = np.minimum(ancestors_min[parent], own)
        start += size
    tree["ancestors_min"] = ancestors_min


def cut(tree, tau):
    """The nodes drawn for threshold tau: every ancestor cut, the node itself not (or not cuttable)."""
    return tree["stop"] & (tree["ancestors_min"] > tau) & ((tree["priority"] <= tau) | tree["terminal"])


def threshold_for_count(count_at, highest, target):
    """The smallest threshold (bisected on a log scale up to twice `highest`) whose cut counts at most
    `target` points by count_at(threshold)."""
    lo, hi = 0.0, float(highest) * 2 + 1
    for _ in range(100):
        mid = math.sqrt(lo * hi) if lo > 0 else hi * 1e-15
        if count_at(mid) > target:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-9 * hi:
            break
    return hi


def cut_with_count(tree, target):
    return cut(tree, threshold_for_count(lambda tau: int(cut(tree, tau).sum()), tree["priority"].max(), target))


def node_cubes(keys, origin, size):
    """The lower corner and edge of each node (index/morton.h: a marker bit, then an octant of three
    bits, x | y << 1 | z << 2, per level from the root)."""
    keys = np.asarray(keys, dtype=np.uint64)
    levels = np.array([(int(k).bit_length() - 1) // 3 for k in keys])
    cell = np.zeros((keys.size, 3), dtype=np.int64)
    for i, (key, level) in enumerate(zip(keys, levels)):
        k = int(key)
        for shift in range(3 * (level - 1), -1, -3):
            octant = (k >> shift) & 7
            cell[i] = 2 * cell[i] + [octant & 1, (octant >> 1) & 1, (octant >> 2) & 1]
    edge = size / 2.0 ** levels
    return np.asarray(origin) + cell * edge[:, None], edge, levels


def store_cut_tree(store, view, width, height):
    """The store's own clusters as a tree, for the renderer's cluster-by-cluster rule (docs/FORMAT.md
    section 4): every point of every node whose cube may reach into the view, each with its parent
    (the cluster of the node above that holds it, by the child_cluster column) and its bound E of the
    error of drawing it instead of what lies below it."""
    info = store.info()["epochs"][0]
    origin, size = np.array(info["cube_origin"]), float(info["cube_size"])
    position, forward, right, up = camera_basis(view)
    focal = 0.5 * height / math.tan(math.radians(view["fov"]) / 2)
    tan_v = 0.5 * height / focal
    tan_h = 0.5 * width / focal
    # Inward side planes of the view's frustum through the camera: a sphere (c, r) may reach in
    # when m . (c - camera) <= r for each outward normal m, and its depth is within near and far.
    outward = [(s * axis - t * forward) / math.sqrt(1 + t * t)
               for axis, t in ((right, tan_h), (up, tan_v)) for s in (1, -1)]
    counts, kept = {}, {}
    for level in range(22):
        found = False
        for block in store.blocks(level=level, columns=["weight", "smoothing", "child_cluster", "refine_bound"]):
            key = int(block["node"])
            counts[key] = block["weight"].size
            if block["level"] != level or key in kept:
                continue
            found = True
            if level > 0 and (key >> 3) not in kept:
                continue  # its parent is out of view, so it is too
            corner, edge, _ = node_cubes([key], origin, size)
            centre = corner[0] + 0.5 * edge[0] - position
            # The node's sphere, grown by the widest blob of its points.
            radius = edge[0] * math.sqrt(3) / 2 + float(block["smoothing"].max(initial=0.0))
            depth = centre @ forward
            if depth + radius < view["near"] or depth - radius > view["far"]:
                continue
            if any(m @ centre > radius for m in outward):
                continue
            kept[key] = block
        if not found:
            break
    keys = sorted(kept, key=lambda k: ((k.bit_length() - 1) // 3, k))
    base, total = {}, 0
    for key in keys:
        base[key] = total
        total += kept[key]["weight"].size
    parent = np.full(total, -1, dtype=np.int64)
    for key in keys:
        links = kept[key]["child_cluster"]
        if links.size == 0:
            continue
        start = 0
        for octant in range(8):
            child = (key << 3) | octant
            n = counts.get(child, 0)
            if child in kept:
                parent[base[child]:base[child] + n] = base[key] + links[start:start + n]
            start += n
    tree = {"position": np.concatenate([kept[k]["position"] for k in keys]),
            "weight": np.concatenate([kept[k]["weight"] for k in keys]),
            "smoothing": np.concatenate([kept[k]["smoothing"] for k in keys]),
            "bound": np.concatenate([kept[k]["refine_bound"] for k in keys]).astype(np.float64),
            "inner": np.concatenate([np.full(kept[k]["weight"].size, kept[k]["child_cluster"].size > 0)
                                     for k in keys]),
            "parent": parent, "focal": focal, "nodes": len(keys)}
    distance = np.linalg.norm(tree["position"] - position, axis=1)
    gap = np.maximum(distance - tree["bound"][:, 0], 0.0)
    a, r = tree["bound"][:, 1], tree["bound"][:, 2]
    q = (PIXEL / focal) ** 2
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        spread = a / (q * gap * gap)
        bounded = spread / np.sqrt(1 + spread / np.maximum(r, 1e-300))
        error = np.where(tree["inner"] & (a > 0) & (r > 0), np.where(np.isfinite(spread), bounded, np.inf), 0.0)
    tree["error"] = error
    has_parent = parent >= 0
    tree["parent_error"] = np.where(has_parent, error[np.maximum(parent, 0)], np.inf)
    return tree


def store_cut(tree, tau):
    """The points the renderer's rule draws for threshold tau: E <= tau, the parent's E > tau."""
    return (tree["error"] <= tau) & (tree["parent_error"] > tau)


def store_cut_with_count(tree, target, in_view):
    """The cut whose points in view come nearest `target` from below."""
    finite = tree["error"][np.isfinite(tree["error"])]  # infinite where the camera is inside a cluster's sphere
    tau = threshold_for_count(lambda t: int((store_cut(tree, t) & in_view).sum()), finite.max(initial=0.0), target)
    return store_cut(tree, tau)


def write_gadget2(path, positions, masses, smoothing):
    """A format-2 GADGET file of gas particles with masses and smoothing lengths."""
    n = positions.shape[0]

    def block(f, label, payload):
        f.write(struct.pack("<i4sii", 8, label.encode(), len(payload) + 8, 8))
        f.write(struct.pack("<i", len(payload)))
        f.write(payload)
        f.write(struct.pack("<i", len(payload)))

    header = struct.pack("<6i6dddii6Iii4d", n, 0, 0, 0, 0, 0, *([0.0] * 6), 1.0, 0.0, 0, 0,
                         n, 0, 0, 0, 0, 0, 0, 1, 0.0, 0.3, 0.7, 0.7)
    header += b"\0" * (256 - len(header))
    with open(path, "wb") as f:
        block(f, "HEAD", header)
        block(f, "POS ", positions.astype("<f4").tobytes())
        block(f, "VEL ", np.zeros((n, 3), "<f4").tobytes())
        block(f, "ID  ", np.arange(1, n + 1, dtype="<u4").tobytes())
        block(f, "MASS", masses.astype("<f4").tobytes())
        block(f, "HSML", smoothing.astype("<f4").tobytes())


def compare(reference, picture):
    """PSNR and SSIM of `picture` against `reference` on the grey log scale."""
    brightness = error_map.grey_scale(reference, "the reference")
    truth, grey = brightness(reference), brightness(picture)
    mse = np.mean((truth - grey) ** 2)
    psnr = 10 * math.log10(1.0 / max(mse, 1e-30))
    return f"PSNR {psnr:.1f} dB, SSIM {error_map.ssim(truth, grey):.4f} (grey log scale)"


def render_and_compare(snapshot, positions, masses, smoothing, flags, reference, args):
    """Writes a cut as a snapshot, draws it as the reference is drawn, and compares."""
    write_gadget2(snapshot, positions, masses, smoothing)
    picture = snapshot + ".pfm"
    subprocess.run([args.octocosm, "render", args.store, "--reference", snapshot, *flags,
                    "--width", str(args.width), "--height", str(args.height), "-o", picture[:-4] + ".png",
                    "--hdr", picture, "--quiet"],
                   check=True)
    image = error_map.read_pfm(picture)
    return f"{compare(reference, image)}; mass {image.sum():.6g} against the reference's {reference.sum():.6g}"


def measure_store_cut(store, view, flags, reference, counts, args):
    tree = store_cut_tree(store, view, args.width, args.height)
    if not tree["inner"].any():
        sys.exit(f"{args.store}: no inner node carries cluster links (child_cluster, refine_bound): "
                 "ingest it again with --coarse clusters")
    in_view = reaches_view(tree["position"], tree["smoothing"], view, args.width, args.height)
    leaves_in_view = int((in_view & ~tree["inner"]).sum())
    print(f"store: {tree['nodes']} nodes in view, {tree['weight'].size} points, {leaves_in_view} particles in view",
          flush=True)
    full = args.full_detail or leaves_in_view
    for count in counts:
        target = int(round(count * full)) if count < 1 else int(count)
        drawn = store_cut_with_count(tree, target, in_view)
        shown = int((drawn & in_view).sum())
        snapshot = os.path.join(args.work, f"oracle-store-{shown}")
        result = render_and_compare(snapshot, tree["position"][drawn], tree["weight"][drawn],
                                    tree["smoothing"][drawn], flags, reference, args)
        print(f"store cut cluster by cluster: {shown} points in view ({100.0 * shown / full:.2f}% of full detail): "
              f"{result}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--store", required=True)
    parser.add_argument("--reference", required=True, help="the bench's reference-VIEW.pfm")
    parser.add_argument("--view", required=True, help="the bench's camera flags for the view")
    parser.add_argument("--counts", default="0.02,0.05,0.1",
                        help="points to draw: counts, or fractions (< 1) of --full-detail")
    parser.add_argument("--full-detail", type=int, default=0,
                        help="points of the view's full-detail frame, as the bench counts them "
                             "(default: the particles whose blobs reach into the view)")
    parser.add_argument("--grouping", choices=("screen", "world", "store"), default="screen",
                        help="cut cells on the screen, or in space as a tree built once for every view; or cut "
                             "the store's own clusters cluster by cluster with the renderer's bound of their "
                             "error (docs/FORMAT.md section 4)")
    parser.add_argument("--priority", choices=("split", "total"), default="split",
                        help="a cell's priority from its members' spread and their blobs apart, or from its "
                             "blob's whole variance only (what a stored cluster carries)")
    parser.add_argument("--levels-per-step", default="1",
                        help="binary levels between the places a cut may stop (3: refine a cell into ~8); "
                             "several, comma-separated, cut one tree each way")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--work", default="lod-oracle")
    parser.add_argument("--octocosm", default=os.path.join(HERE, "..", "build", "tools", "octocosm"))
    parser.add_argument("frames", nargs="*", help="the bench's saved frames of the view, measured alike")
    args = parser.parse_args()
    try:
        steps = [int(x) for x in args.levels_per_step.split(",")]
        counts = [float(x) for x in args.counts.split(",")]
    except ValueError as e:
        parser.error(f"--levels-per-step and --counts take comma-separated numbers ({e})")
    if min(steps) < 1 or min(counts) <= 0:
        parser.error("--levels-per-step must be at least 1, --counts above 0")
    os.makedirs(args.work, exist_ok=True)
    if octocosm is None:
        sys.exit("lod_oracle.py needs the octocosm Python module: PYTHONPATH=build/python, or install it "
                 "(docs/PYTHON.md)")

    view, flags = parse_view(args.view)
    reference = error_map.read_pfm(args.reference)
    if reference.shape != (args.height, args.width):
        sys.exit(f"{args.reference}: {reference.shape[1]}x{reference.shape[0]} pixels, not the "
                 f"{args.width}x{args.height} of --width and --height")
    store = octocosm.open(args.store)
    if args.grouping == "store":
        measure_store_cut(store, view, flags, reference, counts, args)
        for frame in args.frames:
            print(f"{os.path.basename(frame)}: {compare(reference, error_map.read_pfm(frame))}")
        return
    # A wider frustum, so that the particles just outside the view whose blobs
    # reach into it come too (the widest blob, 127 px, subtends less than the
    # difference at these fields of view); project() keeps the ones that reach.
    wide = min(2 * math.degrees(math.atan(math.tan(math.radians(view["fov"]) / 2)
                                          + 2 * MAX_RADIUS / args.height)), 170.0)
    camera = {"position": view["camera"], "look_at": view["look_at"], "fov_y_degrees": wide,
              "near": view["near"], "far": view["far"]}
    points = store.query(level=21, camera=camera, width=args.width, height=args.height, frustum=True,
                         columns=["weight", "smoothing"])
    p = project(points, view, args.width, args.height)
    n = p["mass"].size
    if n == 0:
        sys.exit(f"{args.store}: no particle reaches into the view {args.view}")
    print(f"{n} particles in view (of {points['weight'].size} in the frustum's blocks)", flush=True)
    full = args.full_detail or n
    k = KERNEL_VARIANCE
    tree = build_tree(p, k, args.grouping, args.priority)
    print(f"tree: {tree['mass'].size} nodes", flush=True)

    position, forward, right, up = camera_basis(view)
    for step in steps:
        allow_stops(tree, step)
        label = f"{args.grouping}, a cut every {step} levels"
        if args.priority == "total":
            label += ", priority total"
        for count in counts:
            target = int(round(count * full)) if count < 1 else int(count)
            drawn = cut_with_count(tree, target)
            mass, u, v, z = (tree[key][drawn] for key in ("mass", "u", "v", "z"))
            radius = np.clip(np.sqrt((tree["spread"][drawn] + tree["blob"][drawn]) / k), MIN_RADIUS, MAX_RADIUS)
            focal = p["focal"]
            positions = (position + z[:, None] * forward + ((u - 0.5 * args.width) * z / focal)[:, None] * right
                         - ((v - 0.5 * args.height) * z / focal)[:, None] * up)
            snapshot = os.path.join(args.work, f"oracle-{args.grouping}-{args.priority}-{step}-{drawn.sum()}")
            result = render_and_compare(snapshot, positions, mass, radius * z / focal, flags, reference, args)
            print(f"oracle ({label}): {drawn.sum()} points ({100.0 * drawn.sum() / full:.2f}% of full detail): "
                  f"{result}", flush=True)
    for frame in args.frames:
        print(f"{os.path.basename(frame)}: {compare(reference, error_map.read_pfm(frame))}")


if __name__ == "__main__":
    try:
        main()
    except subprocess.CalledProcessError as e:
        sys.exit(f"lod_oracle.py: {' '.join(map(str, e.cmd[:2]))} failed (status {e.returncode}; its error above)")
    except OSError as e:
        sys.exit(f"lod_oracle.py: {e}")
    except Exception as e:  # the module's errors name the store and what is wrong
        if octocosm is None or not isinstance(e, octocosm.Error):
            raise
        sys.exit(f"lod_oracle.py: {e}")
