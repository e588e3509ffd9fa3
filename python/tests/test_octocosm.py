"""The Python module against the command-line program on the same store.

Run by ctest (test python_module), which sets PYTHONPATH to the module,
OCTOCOSM_PROGRAM to the octocosm program and OCTOCOSM_SHARED_DATA to the
shared snapshots.
"""
import csv
import io
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

import octocosm

PROGRAM = os.environ.get("OCTOCOSM_PROGRAM", "octocosm")
SHARED_DATA = pathlib.Path(os.environ.get("OCTOCOSM_SHARED_DATA", "/nonexistent"))


def run(*args):
    return subprocess.run([PROGRAM, *map(str, args)], check=True, capture_output=True, text=True).stdout


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A particle-mesh run of 16^3 particles in a box of 100 Mpc/h, three epochs, with IDs and velocities."""
    work = tmp_path_factory.mktemp("pm")
    run("synth", "pm", "-o", work / "sim", "-N", 16, "--outputs", 3, "--steps", 6)
    snapshots = sorted((work / "sim").glob("snap_*"))
    assert len(snapshots) == 3
    run("ingest", *snapshots, "-o", work / "store", "--capacity", 300, "--neighbours", 8)
    return work / "store"


def cli_columns(text):
    """A CSV of `octocosm query` or `follow` as a dict of float64 columns."""
    rows = list(csv.reader(io.StringIO(text)))
    header, body = rows[0], rows[1:]
    return {name: np.array([float(r[i]) for r in body]) for i, name in enumerate(header)}


def test_info_describes_every_epoch(store):
    s = octocosm.open(str(store))
    info = s.info()
    assert s.epochs == 3
    assert len(info["epochs"]) == 3
    for epoch in info["epochs"]:
        assert epoch["points"] == 16**3
        assert epoch["periodic"]
        assert epoch["cube_size"] == pytest.approx(100_000)  # kpc/h, as GADGET writes
    times = [e["time"] for e in info["epochs"]]
    assert times == sorted(times)
    assert "velocity" in info["columns"] and "id" in info["columns"]


def test_a_query_returns_what_the_program_writes(store):
    s = octocosm.open(str(store))
    box = (10_000, 20_000, 0, 60_000, 90_000, 50_000)
    result = s.query(epoch=1, box=box, level=2, columns=["weight", "velocity", "id", "type"], stats=True)
    text = run("query", store, "--epoch", 1, "--box", ",".join(map(str, box)), "--level", 2,
               "--columns", "weight,velocity,id,type", "-q")
    expected = cli_columns(text)
    n = len(expected["x"])
    assert n > 0
    assert result["position"].shape == (n, 3) and result["position"].dtype == np.float64
    assert result["velocity"].shape == (n, 3) and result["velocity"].dtype == np.float32
    assert result["id"].dtype == np.uint64 and result["type"].dtype == np.uint8
    np.testing.assert_array_equal(result["position"][:, 0], expected["x"])
    np.testing.assert_array_equal(result["position"][:, 2], expected["z"])
    np.testing.assert_array_equal(result["weight"], expected["weight"])
    np.testing.assert_array_equal(result["velocity"][:, 1], expected["vy"].astype(np.float32))
    np.testing.assert_array_equal(result["id"], expected["id"].astype(np.uint64))
    assert result["stats"]["points_returned"] == n
    lo, hi = np.array(box[:3]), np.array(box[3:])
    assert np.all((result["position"] >= lo) & (result["position"] <= hi))


def test_mass_is_conserved_at_every_level(store):
    s = octocosm.open(str(store))
    full = s.query(level=21, columns=["weight"])
    assert len(full["weight"]) == 16**3
    total = full["weight"].sum()
    for level in range(4):
        assert s.query(level=level, columns=["weight"])["weight"].sum() == pytest.approx(total, rel=1e-12)


def test_blocks_stream_the_same_points_as_one_query(store):
    s = octocosm.open(str(store))
    sphere = (50_000, 50_000, 50_000, 30_000)
    whole = s.query(sphere=sphere, level=3, columns=["id", "smoothing"])
    blocks = s.blocks(sphere=sphere, level=3, columns=["id", "smoothing"])
    parts = list(blocks)
    assert len(parts) > 1
    assert all(0 <= b["level"] <= 3 for b in parts)
    np.testing.assert_array_equal(np.concatenate([b["position"] for b in parts]), whole["position"])
    np.testing.assert_array_equal(np.concatenate([b["id"] for b in parts]), whole["id"])
    assert blocks.stats["points_returned"] == len(whole["id"])


def test_a_camera_selects_by_screen_error(store):
    s = octocosm.open(str(store))
    camera = {"position": (50_000, 50_000, 250_000), "look_at": (50_000, 50_000, 50_000), "fov_y_degrees": 45}
    coarse = s.query(error=32, camera=camera, width=640, height=360, frustum=True)
    fine = s.query(error=1, camera=camera, width=640, height=360, frustum=True)
    assert 0 < len(coarse["position"]) < len(fine["position"])
    text = run("query", store, "--error", 32, "--camera", "50000,50000,250000", "--look-at", "50000,50000,50000", "--fov", 45,
               "--width", 640, "--height", 360, "--frustum", "-q")
    np.testing.assert_array_equal(coarse["position"][:, 1], cli_columns(text)["y"])


def test_follow_returns_the_programs_trajectories(store, tmp_path):
    s = octocosm.open(str(store))
    ids = s.query(level=21, columns=["id"])["id"][::97]
    tracks = s.follow(ids)
    assert len(tracks["id"]) == 3 * len(ids)
    (tmp_path / "ids.txt").write_text("\n".join(map(str, ids)) + "\n")
    expected = cli_columns(run("follow", store, "--ids", tmp_path / "ids.txt"))
    np.testing.assert_array_equal(tracks["id"], expected["id"].astype(np.uint64))
    np.testing.assert_array_equal(tracks["epoch"], expected["epoch"])
    np.testing.assert_array_equal(tracks["position"][:, 0], expected["x"])
    np.testing.assert_array_equal(tracks["velocity"][:, 2], expected["vz"].astype(np.float32))


def test_errors_are_exceptions_of_their_kind(store, tmp_path):
    with pytest.raises(octocosm.NotFoundError) as missing:
        octocosm.open(str(tmp_path / "no-store"))
    assert isinstance(missing.value, octocosm.Error)
    assert missing.value.kind == "not found"
    s = octocosm.open(str(store))
    with pytest.raises(octocosm.InvalidArgumentError):
        s.query()  # neither level nor error
    with pytest.raises(octocosm.InvalidArgumentError, match="unknown column 'mass'"):
        s.query(level=1, columns=["mass"])
    with pytest.raises(octocosm.InvalidArgumentError, match="epoch 7"):
        s.query(epoch=7, level=1)
    # A damaged block: the query stops with a corruption error naming the file.
    damaged = tmp_path / "damaged"
    shutil.copytree(store, damaged)
    pages = damaged / "epoch-00000.pages"
    data = bytearray(pages.read_bytes())
    page_size = octocosm.open(str(damaged)).info()["page_size"]
    data[page_size + 100] ^= 0xFF  # inside the first block, after the header page
    pages.write_bytes(bytes(data))
    with pytest.raises(octocosm.CorruptionError, match="epoch-00000.pages"):
        octocosm.open(str(damaged)).query(level=21)
    # Cluster by cluster needs a store whose clusters are linked: a sampled one's are not.
    sampled = tmp_path / "sampled"
    snapshot = sorted((store.parent / "sim").glob("snap_*"))[0]
    run("ingest", snapshot, "-o", sampled, "--capacity", 300, "--neighbours", 8, "--coarse", "sample")
    with pytest.raises(octocosm.InvalidArgumentError, match="does not link its clusters"):
        octocosm.open(str(sampled)).render(width=48, height=32, cluster_error=30)
    failed = subprocess.run([PROGRAM, "render", str(sampled), "--cluster-error", "30", "-o", str(tmp_path / "x.png")],
                            capture_output=True, text=True)
    assert failed.returncode != 0 and "does not link its clusters" in failed.stderr


def test_a_picture_is_what_the_program_draws(store, tmp_path):
    s = octocosm.open(str(store))
    camera = {"position": (20_000, 30_000, 260_000), "look_at": (50_000, 50_000, 50_000)}
    picture = s.render(camera=camera, time=1.5, width=96, height=64, error=2)
    assert picture["mass"].shape == (64, 96) and picture["mass"].dtype == np.float64
    assert picture["rgb"].shape == (64, 96, 3) and picture["rgb"].dtype == np.uint8
    assert picture["points_drawn"] > 0 and picture["exposure"] > 0
    run("render", store, "--camera", "20000,30000,260000", "--look-at", "50000,50000,50000", "--time", 1.5,
        "--width", 96, "--height", 64, "--error", 2, "-o", tmp_path / "frame.png")
    import matplotlib.image
    png = np.round(matplotlib.image.imread(tmp_path / "frame.png")[:, :, :3] * 255).astype(np.uint8)
    np.testing.assert_array_equal(picture["rgb"], png)
    # Every particle drawn: the mass in the picture is the mass in view, the same at any level of detail.
    full = s.render(camera=camera, time=1, width=96, height=64, full=True)
    coarse = s.render(camera=camera, time=1, width=96, height=64, error=16)
    assert coarse["points_drawn"] < full["points_drawn"]
    assert coarse["mass"].sum() == pytest.approx(full["mass"].sum(), rel=1e-3)
    # Cluster by cluster: as the program draws it, fewer points, the same mass.
    cut = s.render(camera=camera, time=1, width=96, height=64, cluster_error=30)
    assert 0 < cut["points_drawn"] < full["points_drawn"]
    assert cut["mass"].sum() == pytest.approx(full["mass"].sum(), rel=1e-3)
    run("render", store, "--camera", "20000,30000,260000", "--look-at", "50000,50000,50000", "--time", 1,
        "--width", 96, "--height", 64, "--cluster-error", 30, "-o", tmp_path / "cut.png")
    png = np.round(matplotlib.image.imread(tmp_path / "cut.png")[:, :, :3] * 255).astype(np.uint8)
    np.testing.assert_array_equal(cut["rgb"], png)


def test_a_picture_at_a_redshift_with_particles_highlighted(store):
    s = octocosm.open(str(store))
    epochs = s.info()["epochs"]
    at_redshift = s.render(redshift=epochs[1]["redshift"], width=48, height=32)
    assert at_redshift["time"] == 1
    np.testing.assert_array_equal(at_redshift["rgb"], s.render(time=1, width=48, height=32)["rgb"])
    assert not at_redshift["selected_mass"].any()
    between = s.render(scale_factor=(epochs[1]["time"] + epochs[2]["time"]) / 2, width=48, height=32)
    assert between["time"] == pytest.approx(1.5)
    ids = s.query(epoch=1, level=21, columns=["id"], sphere=(50_000, 50_000, 50_000, 25_000))["id"]
    lit = s.render(time=1, width=48, height=32, select=ids)
    assert 0 < lit["selected_mass"].sum() < lit["mass"].sum()
    assert not np.array_equal(lit["rgb"], at_redshift["rgb"])
    with pytest.raises(octocosm.InvalidArgumentError, match="at most one of"):
        s.render(time=1, redshift=0)


def test_two_stores_draw_in_turn_on_one_thread(store, tmp_path):
    # Each store's renderer has its own OpenGL context: drawing with one must
    # not leave the other drawing into the wrong one.
    other = tmp_path / "other"
    shutil.copytree(store, other)
    a, b = octocosm.open(str(store)), octocosm.open(str(other))
    first = a.render(time=0, width=48, height=32)["rgb"]
    late = b.render(time=2, width=48, height=32)["rgb"]
    assert not np.array_equal(first, late)
    np.testing.assert_array_equal(a.render(time=0, width=48, height=32)["rgb"], first)
    np.testing.assert_array_equal(b.render(time=2, width=48, height=32)["rgb"], late)


NGINX = next((p for p in ("/usr/sbin/nginx", "/usr/local/sbin/nginx") if os.access(p, os.X_OK)), None)


@pytest.fixture(scope="module")
def served(store, tmp_path_factory):
    """The store served by nginx on 127.0.0.1, as docs/REMOTE.md serves one; its URL."""
    import socket
    import time
    if NGINX is None:
        pytest.skip("nginx is not installed (tools/bootstrap.sh installs nginx-light)")
    work = tmp_path_factory.mktemp("nginx")
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    temp_paths = "".join(f"  {kind}_temp_path {work}/{kind};\n" for kind in
                         ("client_body", "proxy", "fastcgi", "uwsgi", "scgi"))
    (work / "nginx.conf").write_text(
        ("user root;\n" if os.geteuid() == 0 else "") +
        f"pid {work}/nginx.pid;\nerror_log {work}/error.log;\nevents {{ worker_connections 64; }}\n"
        f"http {{\n  access_log {work}/access.log;\n{temp_paths}"
        f"  server {{ listen 127.0.0.1:{port}; root {store.parent}; }}\n}}\n")
    subprocess.run([NGINX, "-p", work, "-c", work / "nginx.conf", "-e", work / "error.log"], check=True)
    for _ in range(500):
        with socket.socket() as probe:
            if probe.connect_ex(("127.0.0.1", port)) == 0:
                break
        time.sleep(0.01)
    yield f"http://127.0.0.1:{port}/{store.name}"
    os.kill(int((work / "nginx.pid").read_text()), 15)


def test_a_store_over_http_reads_as_the_directory(store, served, tmp_path):
    local, remote = octocosm.open(str(store)), octocosm.open(served, cache_dir=str(tmp_path / "cache"))
    assert remote.info()["epochs"] == local.info()["epochs"]
    box = (10_000, 20_000, 0, 60_000, 90_000, 50_000)
    a = local.query(epoch=2, box=box, level=21, columns=["velocity", "id"])
    b = remote.query(epoch=2, box=box, level=21, columns=["velocity", "id"])
    for name in ("position", "velocity", "id"):
        np.testing.assert_array_equal(a[name], b[name])
    np.testing.assert_array_equal(remote.render(time=1.5, width=48, height=32)["rgb"],
                                  local.render(time=1.5, width=48, height=32)["rgb"])
    assert any((tmp_path / "cache").rglob("*-*-*"))  # fetched pages kept for the next run
    with pytest.raises(octocosm.NotFoundError, match="no manifest.json there"):
        octocosm.open(served + "-elsewhere")


def test_ingest_builds_the_programs_store(store, tmp_path):
    snapshots = sorted((store.parent / "sim").glob("snap_*"))
    report = octocosm.ingest([str(p) for p in snapshots], str(tmp_path / "store"), capacity=300, neighbours=8,
                             quiet=True)
    assert [e["points"] for e in report["epochs"]] == [16**3] * 3
    # The same blocks, node by node (the page files may place them in another
    # order: builds finish in the order their threads do).
    ours, theirs = octocosm.open(str(tmp_path / "store")), octocosm.open(str(store))
    for epoch in range(3):
        a = {b["node"]: b for b in ours.blocks(epoch=epoch, level=21, columns=["all"])}
        b = {b["node"]: b for b in theirs.blocks(epoch=epoch, level=21, columns=["all"])}
        assert a.keys() == b.keys()
        for node in a:
            for name in a[node]:
                np.testing.assert_array_equal(a[node][name], b[node][name], err_msg=f"{node} {name}")
    with pytest.raises(octocosm.InvalidArgumentError):
        octocosm.ingest([str(snapshots[0])], str(tmp_path / "other"), coarse="median")
    with pytest.raises(octocosm.NotFoundError):
        octocosm.ingest([str(tmp_path / "none")], str(tmp_path / "other"))


def test_ctrl_c_stops_an_ingest_and_leaves_nothing(tmp_path):
    import signal
    import time
    run("synth", "scale", "-o", tmp_path / "snap", "-n", 2_000_000, "--quiet")
    script = ("import sys, octocosm\n"
              "try:\n"
              "    octocosm.ingest([sys.argv[1]], sys.argv[2], quiet=True)\n"
              "    print('finished')\n"
              "except KeyboardInterrupt:\n"
              "    print('interrupted')\n")
    child = subprocess.Popen([sys.executable, "-c", script, tmp_path / "snap" / "snap", tmp_path / "store"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # The ingest takes seconds; its output directory appears as it starts.
    for _ in range(500):
        if (tmp_path / "store").exists():
            break
        time.sleep(0.01)
    time.sleep(0.2)
    sent = time.monotonic()
    child.send_signal(signal.SIGINT)
    out, err = child.communicate(timeout=60)
    assert out.strip() == "interrupted", (out, err)
    assert time.monotonic() - sent < 5
    assert not (tmp_path / "store").exists()


@pytest.mark.skipif(not SHARED_DATA.is_dir(), reason="no ../shared/data")
def test_a_gadget4_series_from_the_shared_data(tmp_path):
    # HDF5, read by the reader process that the octocosm program serves.
    series = sorted((SHARED_DATA / "gadget4_hdf5_galaxy_collision_timeseries").glob("snapshot_00[0-2].hdf5"))
    octocosm.ingest([str(p) for p in series], str(tmp_path / "store"), neighbours=0, quiet=True)
    s = octocosm.open(str(tmp_path / "store"))
    points = s.query(level=21, columns=["id", "weight"])
    assert len(points["id"]) == s.info()["epochs"][0]["points"]
    tracks = s.follow(points["id"][:5])
    assert len(tracks["id"]) == 15
    assert np.all(np.diff(tracks["time"].reshape(5, 3), axis=1) > 0)


def test_the_documented_example_runs(store, tmp_path):
    example = pathlib.Path(__file__).parent.parent / "examples" / "density_projection.py"
    image = tmp_path / "density.png"
    out = subprocess.run([sys.executable, example, store, "2", image], check=True, capture_output=True, text=True,
                         env={**os.environ, "MPLCONFIGDIR": str(tmp_path)}).stdout
    assert image.stat().st_size > 1000
    # The level-4 points carry all the mass: the two numbers printed agree.
    mass, total = [float(w) for w in out.split("mass ")[1].split(" of ")]
    assert mass == pytest.approx(total, rel=1e-5)
