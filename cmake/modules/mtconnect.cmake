# MTConnect (docs/mtconnect_node.md): the client core (documents, HTTP framing, the follower, the
# machine model), mtconnect_node, tests on the responses recorded from the reference agent.
find_package(tinyxml2 REQUIRED)
cnc_core_module(cnc_bridge_mtconnect src/core/mtconnect/documents.cpp src/core/mtconnect/http.cpp src/core/mtconnect/follower.cpp
                src/core/mtconnect/machine_model.cpp src/core/mtconnect/shdr.cpp src/core/mtconnect/shdr_adapter.cpp)
target_link_libraries(cnc_bridge_mtconnect PUBLIC tinyxml2::tinyxml2 yaml-cpp)
# A simulated machine that serves MTConnect (the demo cell's mtconnect_mill): a scripted machine
# (sim_haas_mdc's timeline) through the SHDR adapter core, and the reference agent it starts.
cnc_sim_library(cnc_bridge_mtconnect_sim src/sim/mtconnect/sim_device.cpp)
target_link_libraries(cnc_bridge_mtconnect_sim PUBLIC cnc_bridge_mtconnect cnc_bridge_mdc_sim)
cnc_tool(sim_mtconnect src/sim/sim_mtconnect.cpp)
target_link_libraries(sim_mtconnect cnc_bridge_mtconnect_sim)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_mtconnect test/unit/test_mtconnect_documents.cpp test/unit/test_mtconnect_http.cpp
    test/unit/test_mtconnect_follower.cpp test/unit/test_mtconnect_model.cpp)
  target_link_libraries(test_mtconnect cnc_bridge_mtconnect)
  target_compile_definitions(test_mtconnect PRIVATE MTCONNECT_TEST_DATA="${PROJECT_SOURCE_DIR}/test/data/mtconnect")
  # MTConnect out: the SHDR lines, Devices.xml and the adapter's server, without an agent.
  # With the simulated machine's report (sim_mtconnect).
  cnc_core_gtest(test_mtconnect_adapter test/unit/test_mtconnect_adapter.cpp test/unit/test_mtconnect_sim.cpp)
  target_link_libraries(test_mtconnect_adapter cnc_bridge_mtconnect cnc_bridge_mtconnect_sim)
  target_compile_definitions(test_mtconnect_adapter PRIVATE CNC_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
  # The round trip adapter -> reference agent (cppagent v1.8.0.3, built by scripts/build_cppagent.sh,
  # which scripts/setup.sh runs) -> client; fails, saying how to install the agent, without it.
  set(CNC_MTCONNECT_AGENT "/usr/local/lib/cnc_bridge/cppagent-1.8.0.3/agent" CACHE FILEPATH
      "The reference MTConnect agent the round-trip test runs ($CNC_MTCONNECT_AGENT overrides it)")
  cnc_core_gtest(test_mtconnect_agent test/unit/test_mtconnect_agent.cpp TIME_LIMIT 240)
  target_link_libraries(test_mtconnect_agent cnc_bridge_mtconnect)
  target_compile_definitions(test_mtconnect_agent PRIVATE CNC_MTCONNECT_AGENT_DEFAULT="${CNC_MTCONNECT_AGENT}")
endif()
# The client's HTTP framing and documents, and the adapter's encoding of texts, on arbitrary bytes.
cnc_fuzz_target(fuzz_mtconnect test/fuzz/fuzz_mtconnect.cpp)
if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(mtconnect_node src/ros/nodes/mtconnect_node.cpp src/ros/nodes/mtconnect_params.cpp)
  target_link_libraries(mtconnect_node cnc_bridge_mtconnect)
  # MTConnect out: the cell's machines (their MachineState) served as an SHDR adapter to an agent.
  cnc_node(mtconnect_adapter_node src/ros/nodes/mtconnect_adapter_node.cpp src/ros/nodes/mtconnect_adapter_params.cpp)
  target_link_libraries(mtconnect_adapter_node cnc_bridge_mtconnect)
  if(CATKIN_ENABLE_TESTING)
    find_package(rostest REQUIRED)
    # The node against the reference agent's recorded answers, replayed byte for byte.
    add_rostest(test/rostest/mtconnect_node.test DEPENDENCIES mtconnect_node ${PROJECT_NAME}_generate_messages_py)
    # Out and back in: mtconnect_adapter_node -> the reference agent -> mtconnect_node, two machines.
    add_rostest(test/rostest/mtconnect_round_trip.test DEPENDENCIES mtconnect_adapter_node mtconnect_node
                ${PROJECT_NAME}_generate_messages_py)
  endif()
endif()
