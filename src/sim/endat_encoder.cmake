# Simulated EnDat encoder and the module firmware's EnDat bridge (included by CMakeLists.txt).
add_library(ds1928_sim_endat STATIC
  ${CMAKE_CURRENT_LIST_DIR}/endat_encoder.cpp
  ${CMAKE_CURRENT_LIST_DIR}/encoder_description_yaml.cpp
  ${CMAKE_CURRENT_LIST_DIR}/endat_bridge.cpp)
target_link_libraries(ds1928_sim_endat PUBLIC ds1928_endat ds1928_core ds1928_od PRIVATE yaml-cpp)
