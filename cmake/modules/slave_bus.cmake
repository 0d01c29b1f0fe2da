# slave_bus: the universal-CNC serial array protocol to a master with I2C slaves (WirePacker, CRC-8).
cnc_core_module(cnc_bridge_slave_bus
  src/slave_bus/wire_packer.cpp
  src/slave_bus/array_protocol.cpp
  src/slave_bus/value_codec.cpp
  src/slave_bus/bus_session.cpp
  src/slave_bus/sim_master.cpp)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_slave_bus test/unit/test_slave_bus.cpp test/unit/test_slave_bus_session.cpp)
  target_link_libraries(test_slave_bus cnc_bridge_slave_bus)
endif()
cnc_tool(sim_slave_bus src/sim/sim_slave_bus.cpp)
