# The CAN-I/O bus driver on top of the port layer: the FM254 object codec (pure, part of the port
# library) and the BusDriver for `bus: canio` (own library): the cycle (canio_bus.cpp), the SYNC
# pairing (pure), the register access over SDO stepped by the cycle (canio_sdo.cpp). It is told
# its options (canio_options.hpp); it never reads the configuration.
target_sources(ds1928_canio PRIVATE ${CMAKE_CURRENT_LIST_DIR}/object_codec.cpp
                                    ${CMAKE_CURRENT_LIST_DIR}/sync_pairing.cpp)
add_library(ds1928_canio_bus STATIC ${CMAKE_CURRENT_LIST_DIR}/canio_bus.cpp
                                    ${CMAKE_CURRENT_LIST_DIR}/canio_nmt.cpp
                                    ${CMAKE_CURRENT_LIST_DIR}/canio_sdo.cpp
                                    ${CMAKE_CURRENT_LIST_DIR}/canio_identity.cpp)
target_link_libraries(ds1928_canio_bus PUBLIC ds1928_canio ds1928_od ds1928_core
  Threads::Threads)
