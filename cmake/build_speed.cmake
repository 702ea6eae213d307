# What keeps a fresh build short on two cores (doc/benchmarks.md, "The test command"):
#   - precompiled headers for the headers most files of a group of targets parse (Eigen,
#     yaml-cpp, gtest, ros/ros.h). GCC uses one only where -fPIC/-fPIE, -fopenmp and every -D
#     match those it was made with (-Winvalid-pch with -Werror fails the build otherwise), so a
#     group shares one (REUSE_FROM) only if its targets are built alike: the core libraries
#     above io (one export symbol for all), the ROS wrappers' libraries, the rostest nodes; the
#     OpenMP library and each unit test executable (its own temporary folder) have their own.
#   - -O2 instead of Release's -O3 for what is not the core's numerics (ROS wrappers, nodes,
#     tools' command lines, tests): their speed is not the cell model's, and without
#     -ffast-math the two levels compute the same numbers. The core libraries and the
#     benchmarks (whose figures are speeds) keep -O3.
# NURSING_BED_PCH=OFF builds without precompiled headers (every file then stands on its own
# includes, which is what a check of missing includes wants).
option(NURSING_BED_PCH "Precompiled headers for groups of targets (a faster build)" ON)

# The headers a group's precompiled header holds.
set(NURSING_BED_PCH_CORE <algorithm> <cmath> <map> <memory> <sstream> <stdexcept> <string> <vector>
                         <Eigen/Dense> <yaml-cpp/yaml.h>)
set(NURSING_BED_PCH_ROS <algorithm> <cmath> <map> <memory> <mutex> <sstream> <string> <vector> <ros/ros.h>)
set(NURSING_BED_PCH_BUILD_CHECKS <filesystem> <fstream> <sstream> <string> <vector> <gtest/gtest.h>)
set(NURSING_BED_PCH_CORE_TESTS ${NURSING_BED_PCH_BUILD_CHECKS} <cmath> <map> <Eigen/Dense>)
set(NURSING_BED_PCH_ROS_TESTS <cmath> <map> <string> <vector> <gtest/gtest.h> <ros/ros.h>)

# `owner` precompiles `headers`; every existing target of `users` reuses it.
function(nursing_bed_pch_group owner headers users)
  if(NOT NURSING_BED_PCH OR NOT TARGET ${owner})
    return()
  endif()
  target_precompile_headers(${owner} PRIVATE ${${headers}})
  foreach(user ${users})
    if(TARGET ${user})
      target_precompile_headers(${user} REUSE_FROM ${owner})
    endif()
  endforeach()
endfunction()

# Called once every target exists (end of CMakeLists.txt).
function(nursing_bed_speed_up_build)
  # Shared libraries of a group: one export symbol (the default differs by target, and no
  # source uses it), so that they can share a precompiled header.
  set(core_users nursing_bed_hardware_modbus)
  foreach(domain ${NURSING_BED_CORE_DOMAINS})
    if(NOT domain MATCHES "^(io|physics|fe)$")
      list(APPEND core_users nursing_bed_${domain})
    endif()
  endforeach()
  set(ros_users nursing_bed_nodelets nursing_bed_hardware_plugins)
  set_target_properties(nursing_bed_physics ${core_users} nursing_bed_ros ${ros_users} PROPERTIES
    DEFINE_SYMBOL NURSING_BED_SHARED_LIBRARY)
  # Core libraries (physics and what lies above it, linking it), the OpenMP one apart
  nursing_bed_pch_group(nursing_bed_physics NURSING_BED_PCH_CORE "${core_users}")
  nursing_bed_pch_group(nursing_bed_fe NURSING_BED_PCH_CORE "")
  # ROS wrappers (shared)
  nursing_bed_pch_group(nursing_bed_ros NURSING_BED_PCH_ROS "${ros_users}")
  # Unit tests: each its own (NURSING_BED_TEST_TMP_DIR differs), where it has several files
  foreach(domain ${NURSING_BED_CORE_DOMAINS})
    if(TARGET test_${domain})
      get_target_property(sources test_${domain} SOURCES)
      list(LENGTH sources count)
      if(count GREATER 2)
        nursing_bed_pch_group(test_${domain} NURSING_BED_PCH_CORE_TESTS "")
      endif()
    endif()
  endforeach()
  nursing_bed_pch_group(test_build_checks NURSING_BED_PCH_BUILD_CHECKS "")
  nursing_bed_pch_group(test_ros_unit NURSING_BED_PCH_ROS_TESTS "")
  # The rostest nodes, on their shared main's
  nursing_bed_pch_group(nursing_bed_rostest_main NURSING_BED_PCH_ROS_TESTS "${NURSING_BED_ROSTEST_NODE_TARGETS}")

  # -O2 for every target but the core libraries and the benchmarks
  get_property(targets DIRECTORY ${PROJECT_SOURCE_DIR} PROPERTY BUILDSYSTEM_TARGETS)
  foreach(target ${targets})
    get_target_property(type ${target} TYPE)
    if(type MATCHES "^(EXECUTABLE|STATIC_LIBRARY|SHARED_LIBRARY|MODULE_LIBRARY|OBJECT_LIBRARY)$"
       AND NOT target IN_LIST NURSING_BED_CORE_LIBRARIES AND NOT target MATCHES "^bench_")
      target_compile_options(${target} PRIVATE $<$<CONFIG:Release>:-O2>)
    endif()
  endforeach()
endfunction()
