# at_protocol: the '@'-terminated controller protocol with 1 ms setpoint streaming (issue 7).
# Core library (codec, sequencing rules, trajectory planner, sender thread), its unit tests, the
# controller simulator, the streaming benchmark tool, the fuzz target, and at_controller_node.
cnc_core_module(cnc_bridge_at_protocol
  src/at_protocol/codec.cpp
  src/at_protocol/sequencer.cpp
  src/at_protocol/planner.cpp
  src/at_protocol/sender.cpp)

if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_at_protocol
    test/unit/test_at_codec.cpp
    test/unit/test_at_sequencer.cpp
    test/unit/test_at_planner.cpp
    test/unit/test_at_sender.cpp)
  target_link_libraries(test_at_protocol cnc_bridge_at_protocol)
endif()

