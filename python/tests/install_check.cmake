# The installed module, away from the build tree: cmake --install into
# PREFIX, then python3 with only PREFIX/MODULE_DIR on its path imports it,
# queries a store, and, with ../shared/data, ingests an HDF5 snapshot, whose
# reader process is the program installed in PREFIX/bin.
#   cmake -DBUILD=... -DPREFIX=... -DPYTHON=... -DMODULE_DIR=... -DSHARED_DATA=... -P install_check.cmake
file(REMOVE_RECURSE "${PREFIX}")
execute_process(COMMAND ${CMAKE_COMMAND} --install "${BUILD}" --prefix "${PREFIX}" OUTPUT_QUIET
                RESULT_VARIABLE status)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "cmake --install failed: ${status}")
endif()
set(snapshot "${SHARED_DATA}/gadget4_hdf5_galaxy_collision_timeseries/snapshot_000.hdf5")
if(NOT EXISTS "${snapshot}")
  set(snapshot "")
endif()
set(script "
import os, subprocess, sys
import octocosm
prefix = sys.argv[1]
assert octocosm.__file__.startswith(prefix), octocosm.__file__
work = os.path.join(prefix, 'work')
os.makedirs(work, exist_ok=True)
program = os.path.join(prefix, 'bin', 'octocosm')
subprocess.run([program, 'synth', 'pm', '-o', os.path.join(work, 'sim'), '-N', '8', '--steps', '2'], check=True,
               capture_output=True)
octocosm.ingest([os.path.join(work, 'sim', 'snap_000')], os.path.join(work, 'store'), neighbours=0, quiet=True)
assert len(octocosm.open(os.path.join(work, 'store')).query(level=21)['position']) == 8 ** 3
if sys.argv[2]:
    octocosm.ingest([sys.argv[2]], os.path.join(work, 'hdf5'), neighbours=0, quiet=True)
    print('installed module: HDF5 read through', program)
print('installed module: ok')
")
execute_process(COMMAND ${CMAKE_COMMAND} -E env --unset=OCTOCOSM_PROGRAM "PYTHONPATH=${PREFIX}/${MODULE_DIR}"
                        ${PYTHON} -c "${script}" "${PREFIX}" "${snapshot}"
                WORKING_DIRECTORY "${PREFIX}" RESULT_VARIABLE status)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "the installed module failed: ${status}")
endif()
