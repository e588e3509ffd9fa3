# pip install of the source path, as docs/PYTHON.md gives it: a virtual
# environment at PREFIX (seeing Debian's numpy and setuptools), pip install
# ./python into it with this build (OCTOCOSM_BUILD_DIR), then the
# environment's python3 runs installed_smoke.py.
#   cmake -DSOURCE=... -DBUILD=... -DPREFIX=... -DPYTHON=... -DSHARED_DATA=... -P pip_check.cmake
file(REMOVE_RECURSE "${PREFIX}")
execute_process(COMMAND ${PYTHON} -m venv --system-site-packages "${PREFIX}" RESULT_VARIABLE status)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "python3 -m venv failed: ${status} (Debian: python3-venv)")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -E env "OCTOCOSM_BUILD_DIR=${BUILD}"
                        "${PREFIX}/bin/pip" install --no-build-isolation --no-index --no-deps "${SOURCE}/python"
                OUTPUT_QUIET RESULT_VARIABLE status)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "pip install ${SOURCE}/python failed: ${status}")
endif()
include(${CMAKE_CURRENT_LIST_DIR}/installed_smoke.cmake)
run_installed_smoke("${PREFIX}/bin/python3" "${PREFIX}" "${SHARED_DATA}" "the module pip installed"
                    --unset=OCTOCOSM_PROGRAM --unset=PYTHONPATH)
