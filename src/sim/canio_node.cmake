# Simulated CAN-I/O node (bus controller hosting simulated X20DS1928 modules in function model
# 254); included by src/sim/CMakeLists.txt.
if(TARGET ds1928_canio)
  add_library(ds1928_sim_canio STATIC ${CMAKE_CURRENT_LIST_DIR}/canio_node.cpp)
  target_link_libraries(ds1928_sim_canio PUBLIC ds1928_sim ds1928_canio ds1928_od)
endif()
