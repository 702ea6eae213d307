# The ROS-free core is split by domain, one library each. A domain may include only itself and
# the domains its NURSING_BED_CORE_ALLOWED_<domain> lists (all below it); no core file may
# include a ROS header. nursing_bed_check_core_layering()
# fails (FATAL_ERROR naming the file and the include) if a file breaks either rule. It runs at
# configure time from CMakeLists.txt, and in script mode (cmake -DROOT=... -P
# cmake/check_core_layering.cmake) from the unit test that feeds it a bad include.

# Domains, lowest first (README "What is where"), and what each one's files include besides
# itself: exactly that, since CMakeLists.txt links each domain's library to these and nothing
# else (a tool or test linking a domain gets only what that domain uses).
set(NURSING_BED_CORE_DOMAINS io physics observer hardware control bed gap fe rig)
# Parameter tables, YAML and the package folder's lookup.
set(NURSING_BED_CORE_ALLOWED_io "")
# The cell model: gas, orifices, membrane, structure, effects.
set(NURSING_BED_CORE_ALLOWED_physics io)
# The cell observer (what a cell's readings say about its gas and load).
set(NURSING_BED_CORE_ALLOWED_observer io physics)
# The cell hardware boundary and its drivers (simulated, Modbus TCP).
set(NURSING_BED_CORE_ALLOWED_hardware io physics)
# The airbag controller runs the observer and reads and writes cells through the hardware.
set(NURSING_BED_CORE_ALLOWED_control io physics observer hardware)
# The bed: cell grid, body model, posture plans and the manager's policy (rate limits).
set(NURSING_BED_CORE_ALLOWED_bed io physics control)
# The sim-to-real gap diagnosis.
set(NURSING_BED_CORE_ALLOWED_gap io physics)
# The FE membrane model of one airbag.
set(NURSING_BED_CORE_ALLOWED_fe io physics)
# The rig emulator: Modbus TCP servers over simulated cells, a test rig and bench tool (not the
# bed's driver, so neither the hardware nor the control side links it).
set(NURSING_BED_CORE_ALLOWED_rig io physics hardware)

function(nursing_bed_check_core_layering root)
  # The lists themselves: a domain may only use domains listed before it (no cycles).
  set(below "")
  foreach(domain ${NURSING_BED_CORE_DOMAINS})
    foreach(used ${NURSING_BED_CORE_ALLOWED_${domain}})
      list(FIND below "${used}" found)
      if(found EQUAL -1)
        message(FATAL_ERROR "core layering: NURSING_BED_CORE_ALLOWED_${domain} lists '${used}', which is not "
                            "before '${domain}' in NURSING_BED_CORE_DOMAINS (${NURSING_BED_CORE_DOMAINS})")
      endif()
    endforeach()
    list(APPEND below ${domain})
  endforeach()
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
                              "'${target_domain}', which it does not list (NURSING_BED_CORE_ALLOWED_${domain}: "
                              "${NURSING_BED_CORE_ALLOWED_${domain}}): ${line}")
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
