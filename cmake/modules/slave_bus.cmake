# slave_bus: the universal-CNC serial array protocol to a master with I2C slaves (WirePacker, CRC-8).
cnc_core_module(cnc_bridge_slave_bus
  src/core/slave_bus/wire_packer.cpp
  src/core/slave_bus/array_protocol.cpp
  src/core/slave_bus/value_codec.cpp
  src/core/slave_bus/bus_session.cpp
  src/core/slave_bus/slave_table.cpp
  src/core/slave_bus/step_queue.cpp
  src/core/slave_bus/bus_monitor.cpp
  src/core/slave_bus/bus_runner.cpp)
# The simulated master (a peer model, not shipped in the protocol library): sim_slave_bus and tests.
cnc_sim_library(cnc_bridge_slave_bus_sim src/sim/slave_bus/sim_master.cpp)
target_link_libraries(cnc_bridge_slave_bus_sim PUBLIC cnc_bridge_slave_bus)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_slave_bus test/unit/test_slave_bus.cpp test/unit/test_slave_bus_session.cpp
    test/unit/test_slave_bus_table.cpp test/unit/test_slave_bus_runner.cpp)
  target_link_libraries(test_slave_bus cnc_bridge_slave_bus_sim)
endif()
cnc_tool(sim_slave_bus src/sim/sim_slave_bus.cpp)
target_link_libraries(sim_slave_bus cnc_bridge_slave_bus_sim cnc_bridge_testing)
cnc_tool(bench_slave_bus bench/slave_bus/bench_slave_bus.cpp)
target_link_libraries(bench_slave_bus cnc_bridge_testing)
cnc_fuzz_target(fuzz_slave_bus_uplink test/fuzz/fuzz_slave_bus_uplink.cpp)
cnc_fuzz_target(fuzz_slave_bus_master test/fuzz/fuzz_slave_bus_master.cpp)
if(CNC_BRIDGE_FUZZ)
  target_link_libraries(fuzz_slave_bus_master cnc_bridge_slave_bus_sim)
endif()
if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(slave_bus_node src/ros/nodes/slave_bus_node.cpp src/ros/nodes/slave_bus_params.cpp)
  target_link_libraries(slave_bus_node cnc_bridge_slave_bus)
  if(CATKIN_ENABLE_TESTING)
    add_rostest_gtest(test_slave_bus_node test/rostest/slave_bus_node.test test/rostest/test_slave_bus_node.cpp)
    target_link_libraries(test_slave_bus_node ${catkin_LIBRARIES} cnc_bridge_slave_bus)
    add_dependencies(test_slave_bus_node slave_bus_node sim_slave_bus ${PROJECT_NAME}_generate_messages_cpp)
    add_rostest_gtest(test_slave_bus_link test/rostest/slave_bus_link.test test/rostest/test_slave_bus_link.cpp)
    target_link_libraries(test_slave_bus_link ${catkin_LIBRARIES})
    add_dependencies(test_slave_bus_link slave_bus_node sim_slave_bus ${PROJECT_NAME}_generate_messages_cpp)
  endif()
endif()
