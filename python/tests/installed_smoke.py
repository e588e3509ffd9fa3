"""The installed module away from the build tree (run by install_check.cmake and pip_check.cmake):
python3 imports it from PREFIX, queries a store, and, with a snapshot of ../shared/data, ingests an
HDF5 snapshot, whose reader process is the program installed in PREFIX/bin.

    python3 installed_smoke.py PREFIX [HDF5_SNAPSHOT]
"""
import os
import subprocess
import sys

import octocosm

prefix = sys.argv[1]
snapshot = sys.argv[2] if len(sys.argv) > 2 else ""
assert octocosm.__file__.startswith(prefix), octocosm.__file__
work = os.path.join(prefix, "work")
os.makedirs(work, exist_ok=True)
program = os.path.join(prefix, "bin", "octocosm")
subprocess.run([program, "synth", "pm", "-o", os.path.join(work, "sim"), "-N", "8", "--steps", "2"], check=True,
               capture_output=True)
octocosm.ingest([os.path.join(work, "sim", "snap_000")], os.path.join(work, "store"), neighbours=0, quiet=True)
assert len(octocosm.open(os.path.join(work, "store")).query(level=21)["position"]) == 8 ** 3
if snapshot:
    octocosm.ingest([snapshot], os.path.join(work, "hdf5"), neighbours=0, quiet=True)
    print("installed module: HDF5 read through", program)
print("installed module: ok")
