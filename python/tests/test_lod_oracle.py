"""bench/lod_oracle.py on a small clustered set: the oracle's merged points,
drawn by the reference renderer, reproduce the reference when none are merged
and lose detail, but no mass, when few are kept.

Run by ctest (test python_module) with the module on PYTHONPATH and
OCTOCOSM_PROGRAM naming the program.
"""
import os
import pathlib
import re
import subprocess
import sys

import pytest

PROGRAM = os.environ.get("OCTOCOSM_PROGRAM", "octocosm")
ORACLE = pathlib.Path(__file__).resolve().parents[2] / "bench" / "lod_oracle.py"


def run(*args):
    return subprocess.run([*map(str, args)], check=True, capture_output=True, text=True).stdout


VIEW = "--camera 30000,32000,40000 --look-at 25000,25000,25000 --fov 60 --near 1 --far 200000"


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A small clustered set, its store and the reference picture of VIEW at 320x180."""
    work = tmp_path_factory.mktemp("oracle")
    run(PROGRAM, "synth", "scale", "-n", 40000, "--box", 50, "-o", work / "snap")
    run(PROGRAM, "ingest", work / "snap" / "snap", "-o", work / "store", "--capacity", 2000, "-q")
    run(PROGRAM, "render", work / "store", "--reference", work / "snap" / "snap", *VIEW.split(),
        "--width", 320, "--height", 180, "-o", work / "reference.png", "--hdr", work / "reference.pfm", "-q")
    return work


def oracle(scene, view, *args):
    return subprocess.run([sys.executable, ORACLE, "--store", scene / "store", "--reference", scene / "reference.pfm",
                           "--view", view, "--width", "320", "--height", "180", "--work", scene / "oracle",
                           "--octocosm", PROGRAM, *map(str, args)], capture_output=True, text=True)


@pytest.mark.parametrize("grouping, levels", [("screen", 1), ("world", 3)])
def test_the_oracle_reproduces_the_reference_from_every_particle_and_keeps_the_mass(scene, grouping, levels):
    result = oracle(scene, VIEW, "--counts", "0.1,1e9", "--grouping", grouping, "--levels-per-step", levels)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    rows = re.findall(r"oracle \(.*\): (\d+) points .*PSNR ([\d.]+) dB, SSIM ([\d.]+) .*"
                      r"mass ([\d.e+]+) against the reference's ([\d.e+]+)", out)
    assert len(rows) == 2, out
    (few, few_db, few_ssim, few_mass, mass), (every, every_db, every_ssim, every_mass, _) = rows
    in_view = int(re.search(r"(\d+) particles in view", out).group(1))
    assert int(every) == in_view
    assert float(every_db) > 80, out  # every particle its own point: the reference to float rounding
    assert float(every_ssim) > 0.9999
    assert float(every_mass) == pytest.approx(float(mass), rel=1e-5)
    assert int(few) == pytest.approx(0.1 * in_view, rel=0.05)
    assert 15 < float(few_db) < float(every_db), out
    assert 0.5 < float(few_ssim) < float(every_ssim), out
    # Merged blobs that reach past the image's edge move some mass across it.
    assert float(few_mass) == pytest.approx(float(mass), rel=0.01)


def test_a_view_without_particles_is_an_error_naming_the_store(scene):
    result = oracle(scene, "--camera 25000,25000,-90000 --look-at 25000,25000,-200000 --near 1 --far 1000")
    assert result.returncode != 0
    assert "no particle reaches into the view" in result.stderr and str(scene / "store") in result.stderr
    assert "Traceback" not in result.stderr


def test_the_store_cut_draws_each_particle_once_and_every_particle_at_the_finest(scene):
    """--grouping store: the renderer's cluster-by-cluster rule on the store's own clusters."""
    result = oracle(scene, VIEW, "--counts", "0.1,1e9", "--grouping", "store")
    assert result.returncode == 0, result.stderr
    out = result.stdout
    rows = re.findall(r"store cut cluster by cluster: (\d+) points in view .*PSNR ([\d.]+) dB, SSIM ([\d.]+) .*"
                      r"mass ([\d.e+]+) against the reference's ([\d.e+]+)", out)
    assert len(rows) == 2, out
    (few, few_db, _, few_mass, mass), (every, every_db, every_ssim, every_mass, _) = rows
    in_view = int(re.search(r"(\d+) particles in view", out).group(1))
    assert int(every) == in_view
    assert float(every_db) > 80, out  # the leaves carry the reference's smoothing lengths
    assert float(every_ssim) > 0.9999
    assert float(every_mass) == pytest.approx(float(mass), rel=1e-5)
    assert 0.08 * in_view < int(few) <= 0.1 * in_view
    assert 15 < float(few_db) < float(every_db), out
    assert float(few_mass) == pytest.approx(float(mass), rel=0.01)


def test_the_store_cut_of_a_store_without_cluster_links_is_an_error(scene):
    run(PROGRAM, "ingest", scene / "snap" / "snap", "-o", scene / "sampled", "--capacity", 2000, "--coarse", "sample",
        "-q")
    result = subprocess.run([sys.executable, ORACLE, "--store", scene / "sampled", "--reference",
                             scene / "reference.pfm", "--view", VIEW, "--width", "320", "--height", "180",
                             "--work", scene / "oracle", "--octocosm", PROGRAM, "--grouping", "store"],
                            capture_output=True, text=True)
    assert result.returncode != 0
    assert "no inner node carries cluster links" in result.stderr and str(scene / "sampled") in result.stderr
    assert "Traceback" not in result.stderr
