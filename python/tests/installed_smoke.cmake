# run_installed_smoke(PYTHON PREFIX SHARED_DATA WHAT [ENV...]): runs
# installed_smoke.py with PYTHON under `cmake -E env ENV...` in PREFIX, with an
# HDF5 snapshot of SHARED_DATA where there is one; WHAT names the module in
# the failure message.
function(run_installed_smoke python prefix shared_data what)
  set(snapshot "${shared_data}/gadget4_hdf5_galaxy_collision_timeseries/snapshot_000.hdf5")
  if(NOT EXISTS "${snapshot}")
    set(snapshot "")
  endif()
  execute_process(COMMAND ${CMAKE_COMMAND} -E env ${ARGN}
                          ${python} ${CMAKE_CURRENT_FUNCTION_LIST_DIR}/installed_smoke.py "${prefix}" "${snapshot}"
                  WORKING_DIRECTORY "${prefix}" RESULT_VARIABLE status)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "${what} failed: ${status}")
  endif()
endfunction()
