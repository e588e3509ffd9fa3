# The installed module, away from the build tree: cmake --install into
# PREFIX, then python3 with only PREFIX/MODULE_DIR on its path runs
# installed_smoke.py.
#   cmake -DBUILD=... -DPREFIX=... -DPYTHON=... -DMODULE_DIR=... -DSHARED_DATA=... -P install_check.cmake
file(REMOVE_RECURSE "${PREFIX}")
execute_process(COMMAND ${CMAKE_COMMAND} --install "${BUILD}" --prefix "${PREFIX}" OUTPUT_QUIET
                RESULT_VARIABLE status)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "cmake --install failed: ${status}")
endif()
include(${CMAKE_CURRENT_LIST_DIR}/installed_smoke.cmake)
run_installed_smoke(${PYTHON} "${PREFIX}" "${SHARED_DATA}" "the installed module"
                    --unset=OCTOCOSM_PROGRAM "PYTHONPATH=${PREFIX}/${MODULE_DIR}")
