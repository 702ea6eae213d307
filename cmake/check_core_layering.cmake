# Script mode: cmake -DROOT=<package root> -P cmake/check_core_layering.cmake
if(NOT ROOT)
  message(FATAL_ERROR "check_core_layering: pass -DROOT=<package root>")
endif()
include(${CMAKE_CURRENT_LIST_DIR}/core_layering.cmake)
nursing_bed_check_core_layering(${ROOT})
message(STATUS "core layering: ok")
