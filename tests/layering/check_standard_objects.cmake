# POWERLINK's standard objects are data: no object index of the communication profile area
# (0x1000..0x1FFF) is typed in the product code outside powerlink/standard_objects.hpp.
# Comments may name an index; code and strings may not. CAN-I/O (CiA 301) and the CANopen and
# CAN layers are another protocol and are not checked: src/can*, src/sim/canio_node*, and lines
# of the product that speak of them are listed in ALLOWED below, each with its reason.
# SELF_TEST=ON: a planted hex index is found (the check can fail).
cmake_minimum_required(VERSION 3.20)

# Lines allowed although they hold such a number ("file|text" substrings).
set(ALLOWED
    # EPSG DS 301 error entry type bit field, not an object index.
    "src/powerlink/error_signalling.hpp|kModeActive = 0x1000"
    # CiA 301 heartbeat producer time of a CAN-I/O node (config_canio: another protocol).
    "src/config/config_canio.cpp|object 0x1017 is 16 bit"
    # CiA 301 identity objects of a CAN-I/O node (the CAN-I/O expected topology).
    "src/config/config_canio.cpp|an expected identity (0x1000 / 0x1018)"
    "daemon/canio_metrics.cpp|CAN-I/O node's identity (0x1000 / 0x1018)")

function(check_file path rel out)
  # One list element per line: the list separator and brackets in code become harmless.
  file(READ "${path}" content)
  string(REPLACE ";" "," content "${content}")
  string(REPLACE "[" "(" content "${content}")
  string(REPLACE "]" ")" content "${content}")
  string(REPLACE "\\" "/" content "${content}")
  string(REPLACE "\n" ";" lines "${content}")
  set(found "")
  set(n 0)
  foreach(line IN LISTS lines)
    math(EXPR n "${n} + 1")
    string(REGEX REPLACE "//.*$" "" code "${line}")
    if(code MATCHES "0[xX]1[0-9A-Fa-f][0-9A-Fa-f][0-9A-Fa-f]([^0-9A-Fa-f']|$)")
      set(ok FALSE)
      foreach(a IN LISTS ALLOWED)
        string(REPLACE "|" ";" parts "${a}")
        list(GET parts 0 afile)
        list(GET parts 1 atext)
        string(FIND "${line}" "${atext}" pos)
        if(afile STREQUAL rel AND NOT pos EQUAL -1)
          set(ok TRUE)
        endif()
      endforeach()
      if(NOT ok)
        list(APPEND found "${rel}:${n}: ${line}")
      endif()
    endif()
  endforeach()
  set(${out} "${found}" PARENT_SCOPE)
endfunction()

if(SELF_TEST)
  file(WRITE "${WORK_DIR}/planted.cpp" "// 0x1018 in a comment is fine\nint x = f(0x1018, 1);\n")
  check_file("${WORK_DIR}/planted.cpp" "src/powerlink/planted.cpp" hits)
  list(LENGTH hits count)
  if(NOT count EQUAL 1)
    message(FATAL_ERROR "self test: expected the planted index once, found ${count}: ${hits}")
  endif()
  message(STATUS "self test: planted index found")
  return()
endif()

file(GLOB_RECURSE files RELATIVE "${SOURCE_DIR}" "${SOURCE_DIR}/src/*.cpp" "${SOURCE_DIR}/src/*.hpp"
     "${SOURCE_DIR}/daemon/*.cpp" "${SOURCE_DIR}/daemon/*.hpp")
set(all "")
foreach(rel IN LISTS files)
  if(rel MATCHES "^src/can(io)?/" OR rel MATCHES "^src/sim/canio_node"
     OR rel STREQUAL "src/powerlink/standard_objects.hpp")
    continue()
  endif()
  check_file("${SOURCE_DIR}/${rel}" "${rel}" hits)
  list(APPEND all ${hits})
endforeach()
list(LENGTH all count)
if(count GREATER 0)
  list(JOIN all "\n" text)
  message(FATAL_ERROR "POWERLINK object indices typed outside powerlink/standard_objects.hpp "
                      "(name them through powerlink::obj):\n${text}")
endif()
message(STATUS "no POWERLINK object index outside its table")
