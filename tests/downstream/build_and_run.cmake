# cmake -DBUILD_DIR=<stiffsim build> -DWORK_DIR=<scratch> -DMODELS_DIR=<models>
#       -P build_and_run.cmake
# Installs the build into WORK_DIR/prefix, builds tests/downstream against
# that prefix alone (find_package(stiffsim)) and runs its check.
foreach(var BUILD_DIR WORK_DIR MODELS_DIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "build_and_run.cmake: -D${var}=... is required")
  endif()
endforeach()
file(REMOVE_RECURSE "${WORK_DIR}")
set(prefix "${WORK_DIR}/prefix")
execute_process(COMMAND "${CMAKE_COMMAND}" --install "${BUILD_DIR}" --prefix "${prefix}"
                OUTPUT_QUIET COMMAND_ERROR_IS_FATAL ANY)
execute_process(COMMAND "${CMAKE_COMMAND}" -S "${CMAKE_CURRENT_LIST_DIR}" -B "${WORK_DIR}/build"
                        -DCMAKE_BUILD_TYPE=Release "-DCMAKE_PREFIX_PATH=${prefix}"
                COMMAND_ERROR_IS_FATAL ANY)
execute_process(COMMAND "${CMAKE_COMMAND}" --build "${WORK_DIR}/build" COMMAND_ERROR_IS_FATAL ANY)
execute_process(COMMAND "${WORK_DIR}/build/free_fall" "${MODELS_DIR}" COMMAND_ERROR_IS_FATAL ANY)
