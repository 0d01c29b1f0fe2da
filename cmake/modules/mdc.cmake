# Haas Machine Data Collection (issue 9): core library, haas_mdc_node, sim_haas_mdc, tests.
cnc_core_module(cnc_bridge_mdc src/mdc/mdc_protocol.cpp src/mdc/mdc_client.cpp src/mdc/mdc_monitor.cpp
  src/mdc/sim_machine.cpp)
cnc_tool(sim_haas_mdc src/sim/sim_haas_mdc.cpp)
cnc_tool(bench_mdc_poll bench/mdc/bench_mdc_poll.cpp)
cnc_fuzz_target(fuzz_mdc_reply test/fuzz/fuzz_mdc_reply.cpp)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_mdc test/unit/test_mdc_protocol.cpp test/unit/test_mdc_client.cpp test/unit/test_mdc_sim.cpp)
  target_link_libraries(test_mdc cnc_bridge_mdc)
  target_compile_definitions(test_mdc PRIVATE MDC_TEST_DATA="${PROJECT_SOURCE_DIR}/test/data/mdc")
endif()
