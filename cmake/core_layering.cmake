# The ROS-free core is split by domain, one library each. A domain may include only itself and
# the domains below it; no core file may include a ROS header. nursing_bed_check_core_layering()
# fails (FATAL_ERROR naming the file and the include) if a file breaks either rule. It runs at
# configure time from CMakeLists.txt, and in script mode (cmake -DROOT=... -P
# cmake/check_core_layering.cmake) from the unit test that feeds it a bad include.

# Domains, lowest first, and what each may include (besides itself).
set(NURSING_BED_CORE_DOMAINS io physics control bed gap fe observer hardware)
set(NURSING_BED_CORE_ALLOWED_io "")
set(NURSING_BED_CORE_ALLOWED_physics io)
# control runs the observer and reads and writes cells through the hardware boundary.
set(NURSING_BED_CORE_ALLOWED_control io physics observer hardware)
set(NURSING_BED_CORE_ALLOWED_bed io physics control observer hardware)
set(NURSING_BED_CORE_ALLOWED_gap io physics)
set(NURSING_BED_CORE_ALLOWED_fe io physics)
set(NURSING_BED_CORE_ALLOWED_observer io physics)
# The cell hardware boundary and its drivers (simulated, Modbus TCP) and the rig emulator: below
# the control side, which reads and writes cells through it.
set(NURSING_BED_CORE_ALLOWED_hardware io physics)

function(nursing_bed_check_core_layering root)
  foreach(domain ${NURSING_BED_CORE_DOMAINS})
    set(allowed ${domain} ${NURSING_BED_CORE_ALLOWED_${domain}})
    file(GLOB_RECURSE files ${root}/include/nursing_bed/core/${domain}/*
                            ${root}/src/core/${domain}/*)
    foreach(f ${files})
      file(STRINGS ${f} ros_includes
           REGEX "#include *[<\"](ros/|[a-z_]*_msgs/|nodelet/|tf2_ros/|pluginlib/)")
      if(ros_includes)
        message(FATAL_ERROR "core layering: ROS header in the ROS-free core: ${f}: ${ros_includes}")
      endif()
      file(STRINGS ${f} core_includes REGEX "#include *[<\"]nursing_bed/core/")
      foreach(line ${core_includes})
        string(REGEX MATCH "nursing_bed/core/([a-z_]+)/" match "${line}")
        set(target_domain "${CMAKE_MATCH_1}")
        if(NOT match)
          message(FATAL_ERROR "core layering: ${f} includes a core header outside any domain: ${line}")
        endif()
        list(FIND allowed "${target_domain}" found)
        if(found EQUAL -1)
          message(FATAL_ERROR "core layering: ${f} (domain '${domain}') includes domain "
                              "'${target_domain}', which is not below it: ${line}")
        endif()
      endforeach()
    endforeach()
  endforeach()
  # Files directly in core/ or in an unknown folder belong to no domain.
  file(GLOB stray ${root}/include/nursing_bed/core/* ${root}/src/core/*)
  foreach(f ${stray})
    get_filename_component(name ${f} NAME)
    list(FIND NURSING_BED_CORE_DOMAINS "${name}" known)
    if(known EQUAL -1)
      message(FATAL_ERROR "core layering: ${f} is not in a domain folder (${NURSING_BED_CORE_DOMAINS})")
    endif()
  endforeach()
endfunction()
