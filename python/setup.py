"""pip install ./python (from the project's root): builds the module `octocosm` and the octocosm
program with the project's CMake, and installs the module into the environment's site-packages and
the program into its bin/, where the module finds it (it serves the snapshot readers' reader
processes). docs/PYTHON.md.

OCTOCOSM_BUILD_DIR names a build directory to build in (or one already built, as the tests do);
else the build goes to python/build/cmake. Needs the packages tools/bootstrap.sh installs; run pip
with --no-build-isolation so that it uses Debian's setuptools rather than fetching one.
"""
import os
import pathlib
import re
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

PYTHON_DIR = pathlib.Path(__file__).resolve().parent
SOURCE_DIR = PYTHON_DIR.parent
BUILD_DIR = pathlib.Path(os.environ.get("OCTOCOSM_BUILD_DIR", PYTHON_DIR / "build" / "cmake")).resolve()
PROGRAM = BUILD_DIR / "tools" / "octocosm"


def project_version():
    text = (SOURCE_DIR / "CMakeLists.txt").read_text()
    return re.search(r"project\(octocosm VERSION ([0-9.]+)", text).group(1)


class CMakeBuild(build_ext):
    """Configures (where not configured yet) and builds the module and the program."""

    def build_extension(self, ext):
        if not (BUILD_DIR / "CMakeCache.txt").exists():
            subprocess.check_call(["cmake", "-S", str(SOURCE_DIR), "-B", str(BUILD_DIR),
                                   "-DCMAKE_BUILD_TYPE=RelWithDebInfo", f"-DPython3_EXECUTABLE={sys.executable}",
                                   "-DOCTOCOSM_BUILD_TESTS=OFF", "-DOCTOCOSM_BUILD_BENCH=OFF"])
        subprocess.check_call(["cmake", "--build", str(BUILD_DIR), "--target", "octocosm_python", "octocosm",
                               "--parallel", str(os.cpu_count() or 2)])
        built = sorted((BUILD_DIR / "python").glob("octocosm*.so"))
        if not built:
            raise RuntimeError(f"{BUILD_DIR}/python: no module octocosm*.so was built "
                               "(is pybind11-dev installed? tools/bootstrap.sh installs it)")
        target = pathlib.Path(self.get_ext_fullpath(ext.name))
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(built[-1], target)


setup(
    name="octocosm",
    version=project_version(),
    description="Out-of-core octree stores of N-body snapshots: queries, trajectories and pictures as numpy arrays",
    ext_modules=[Extension("octocosm", sources=[])],
    cmdclass={"build_ext": CMakeBuild},
    # The program as a data file: pip copies scripts as text, and it is a binary.
    data_files=[("bin", [str(PROGRAM)])],
    python_requires=">=3.9",
    install_requires=["numpy"],
    zip_safe=False,
)
