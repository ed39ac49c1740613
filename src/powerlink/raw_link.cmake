# Raw-socket link (AF_PACKET) of the POWERLINK library; included by src/powerlink/CMakeLists.txt
# after ds1928_powerlink is defined.
target_sources(ds1928_powerlink PRIVATE ${CMAKE_CURRENT_LIST_DIR}/raw_link.cpp)
target_sources(ds1928_powerlink PRIVATE ${CMAKE_CURRENT_LIST_DIR}/interface_check.cpp)
