# The include graph between the project's folders points one way: down the layers (README.md
# §Layout: core and the codecs at the bottom, then the links and bus drivers, the simulators, the
# services, the configuration, the daemon and the tools on top). A file may
# include its own folder and any folder of a lower layer; an include up or sideways is a
# back-arrow and fails this check, which names the file and the include.
#
#   cmake -DSOURCE_DIR=<tree> -P check_layering.cmake              check a tree
#   cmake -DSELF_TEST=ON -DWORK_DIR=<scratch> -P check_layering.cmake
#                                        plant back-arrows in a scratch tree: the check must see them
cmake_minimum_required(VERSION 3.25)

# Folder → layer. src/<folder>, include/<folder> (the public client API), daemon/, tools/<tool>.
# docs/design.md draws the same map.
set(LAYER_ds1928 0)        # include/ds1928: shared-memory layout, C-compatible
set(LAYER_x20ds1928 0)     # the device: process image, settings, object dictionary (the one register table)
set(LAYER_core 1)          # cycle engine, bus interface, clock, queues, Result, SDO abort codes
set(LAYER_can 2)           # CAN itself: frame, bit time, error frames, ports (SocketCAN, virtual bus)
set(LAYER_endat 2)         # codecs
set(LAYER_flatstream 2)
set(LAYER_powerlink 3)     # links and bus drivers
set(LAYER_canio 3)         # the CAN-I/O bus: options, CANopen codecs, driver
set(LAYER_capture 4)       # taps on the links
set(LAYER_sim 4)           # simulated node and bus (the drivers' test peers)
set(LAYER_shm 5)           # services
set(LAYER_control 5)
set(LAYER_metrics 6)
set(LAYER_service 6)       # the daemon as a system service: log, journal records, sd_notify
set(LAYER_config 7)        # the configuration: gathers every part's options
set(LAYER_daemon 8)        # wiring
set(LAYER_tools 9)

# Sideways includes that are known and allowed, "from>to" with the reason (none today: the
# register facts CAN-I/O took from powerlink/ live in x20ds1928/).
set(SIDEWAYS "")

# Lower folders or single headers a folder must not include although the layers would allow it,
# NEVER_<from> → folders ("canio") or headers ("canio/canio_bus.hpp"), with the reason in
# NEVER_<from>_WHY: the configuration takes the CAN-I/O bus options
# from canio/ and never sees the driver, which only the daemon builds.
set(NEVER_config "canio/canio_bus.hpp")
set(NEVER_config_WHY "the configuration takes the CAN-I/O bus options, never the driver, which only the daemon builds")

# The folder a file belongs to; empty when it is none of the layered ones.
function(folder_of root file out)
  file(RELATIVE_PATH rel "${root}" "${file}")
  # (Two branches: if() evaluates both sides of an OR, the second MATCHES resets CMAKE_MATCH_1.)
  if(rel MATCHES "^src/([^/]+)/")
    set(${out} "${CMAKE_MATCH_1}" PARENT_SCOPE)
  elseif(rel MATCHES "^include/([^/]+)/")
    set(${out} "${CMAKE_MATCH_1}" PARENT_SCOPE)
  elseif(rel MATCHES "^daemon/")
    set(${out} "daemon" PARENT_SCOPE)
  elseif(rel MATCHES "^tools/")
    set(${out} "tools" PARENT_SCOPE)
  else()
    set(${out} "" PARENT_SCOPE)
  endif()
endfunction()

# Appends "file: #include \"x\" (why)" for every back-arrow below `root` to `out`.
function(check_tree root out)
  set(found "")
  file(GLOB_RECURSE files LIST_DIRECTORIES false
       "${root}/src/*.hpp" "${root}/src/*.cpp" "${root}/src/*.h"
       "${root}/include/*.h" "${root}/include/*.hpp"
       "${root}/daemon/*.hpp" "${root}/daemon/*.cpp"
       "${root}/tools/*.hpp" "${root}/tools/*.cpp")
  list(SORT files)
  foreach(f IN LISTS files)
    folder_of("${root}" "${f}" from)
    if(from STREQUAL "")
      continue()
    endif()
    file(RELATIVE_PATH rel "${root}" "${f}")
    if(NOT DEFINED LAYER_${from})
      list(APPEND found "${rel}: folder '${from}' has no layer (add it to ${CMAKE_CURRENT_LIST_FILE})")
      continue()
    endif()
    file(STRINGS "${f}" lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"[^\"]+/[^\"]+\"")
    foreach(line IN LISTS lines)
      string(REGEX MATCH "\"(([^\"/]+)/[^\"]+)\"" _ "${line}")
      set(header "${CMAKE_MATCH_1}")
      set(to "${CMAKE_MATCH_2}")
      if(to STREQUAL from OR NOT DEFINED LAYER_${to})
        continue()  # own folder, or not a project folder (system and library headers)
      endif()
      if(LAYER_${to} GREATER LAYER_${from})
        list(APPEND found "${rel}: #include \"${header}\": ${from} (layer ${LAYER_${from}}) must not include ${to} (layer ${LAYER_${to}})")
      elseif(LAYER_${to} EQUAL LAYER_${from} AND NOT "${from}>${to}" IN_LIST SIDEWAYS)
        list(APPEND found "${rel}: #include \"${header}\": ${from} and ${to} share layer ${LAYER_${to}}; a sideways include needs its reason in SIDEWAYS")
      elseif(to IN_LIST NEVER_${from} OR header IN_LIST NEVER_${from})
        list(APPEND found "${rel}: #include \"${header}\": ${from} must not include ${header} (${NEVER_${from}_WHY})")
      endif()
    endforeach()
  endforeach()
  set(${out} "${found}" PARENT_SCOPE)
endfunction()

if(SELF_TEST)
  # A scratch tree with one clean include and one of each kind of back-arrow: the check must
  # report exactly the three back-arrows.
  set(t "${WORK_DIR}/layering-self-test")
  file(REMOVE_RECURSE "${t}")
  file(WRITE "${t}/src/core/cycle_engine.hpp" "#include \"core/cycle_config.hpp\"\n#include \"config/config.hpp\"\n")
  file(WRITE "${t}/src/config/config.hpp" "#include \"core/cycle_config.hpp\"\n#include \"canio/canio_bus.hpp\"\n#include \"canio/canio_options.hpp\"\n")
  file(WRITE "${t}/src/shm/publisher.hpp" "#  include \"control/socket_config.hpp\"\n#include <vector>\n")
  check_tree("${t}" found)
  file(REMOVE_RECURSE "${t}")
  set(expected
      "src/config/config.hpp: #include \"canio/canio_bus.hpp\": config must not include canio/canio_bus.hpp (${NEVER_config_WHY})"
      "src/core/cycle_engine.hpp: #include \"config/config.hpp\": core (layer ${LAYER_core}) must not include config (layer ${LAYER_config})"
      "src/shm/publisher.hpp: #include \"control/socket_config.hpp\": shm and control share layer ${LAYER_shm}; a sideways include needs its reason in SIDEWAYS")
  if(NOT found STREQUAL expected)
    string(REPLACE ";" "\n  " found "${found}")
    message(FATAL_ERROR "layering self-test: the planted back-arrows were not reported as expected; got:\n  ${found}")
  endif()
  message(STATUS "layering self-test: the 3 planted back-arrows were found")
  return()
endif()

if(NOT SOURCE_DIR)
  message(FATAL_ERROR "usage: cmake -DSOURCE_DIR=<tree> -P check_layering.cmake")
endif()
check_tree("${SOURCE_DIR}" found)
if(found)
  list(LENGTH found n)
  string(REPLACE ";" "\n  " found "${found}")
  message(FATAL_ERROR "${n} include(s) against the layers:\n  ${found}")
endif()
message(STATUS "layering: no include points up or sideways")
