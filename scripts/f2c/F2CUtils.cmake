# Replaces Fields2Cover 2.1.0's cmake/F2CUtils.cmake for terraplan's
# benchmark build (scripts/f2c/build.sh). Only steering_functions is taken,
# from a local source tree (FETCHCONTENT_SOURCE_DIR_STEERING_FUNCTIONS with
# FETCHCONTENT_FULLY_DISCONNECTED=ON: nothing is downloaded). Left out:
# OR-tools (its PyPI wheel ships no headers; the route planner's solver is
# replaced, see no-ortools.patch), matplot++ (plotting only: visualizer.cpp
# is not compiled); nlohmann_json comes from the system (nlohmann-json3-dev).
function(f2c_declare_dependencies)
  include(FetchContent)
  if(NOT FETCHCONTENT_SOURCE_DIR_STEERING_FUNCTIONS)
    message(FATAL_ERROR "steering_functions: set "
      "-DFETCHCONTENT_SOURCE_DIR_STEERING_FUNCTIONS=DIR (its source tree, "
      "commit 13e3f5658144b3832fb1eb31a0e2f5a3cbf57db9)")
  endif()
  FetchContent_Declare(steering_functions
    SOURCE_DIR "${FETCHCONTENT_SOURCE_DIR_STEERING_FUNCTIONS}")
  FetchContent_MakeAvailable(steering_functions)
  find_package(nlohmann_json 3 REQUIRED)
endfunction()
