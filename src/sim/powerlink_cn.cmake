# Simulated POWERLINK Controlled Node (bus controller hosting simulated X20DS1928 modules);
# included by src/sim/CMakeLists.txt.
if(TARGET ds1928_powerlink)
  add_library(ds1928_sim_powerlink STATIC ${CMAKE_CURRENT_LIST_DIR}/powerlink_cn.cpp
              ${CMAKE_CURRENT_LIST_DIR}/powerlink_cn_loop.cpp
              ${CMAKE_CURRENT_LIST_DIR}/powerlink_cn_prc.cpp
              ${CMAKE_CURRENT_LIST_DIR}/cn_object_dictionary.cpp)
  target_link_libraries(ds1928_sim_powerlink PUBLIC ds1928_sim ds1928_powerlink)
endif()
