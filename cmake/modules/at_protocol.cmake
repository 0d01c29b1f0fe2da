# at_protocol: the '@'-terminated controller protocol with 1 ms setpoint streaming
# (docs/protocols/at_protocol.md).
# Core library (codec, sequencing rules, trajectory planner, sender thread, the controller session
# and its diagnostics, the goal runner),
# its unit tests, the controller simulator, the streaming benchmark tool, the fuzz target, and
# at_controller_node.
cnc_core_module(cnc_bridge_at_protocol
  src/core/at_protocol/codec.cpp
  src/core/at_protocol/sequencer.cpp
  src/core/at_protocol/planner.cpp
  src/core/at_protocol/program_path.cpp
  src/core/at_protocol/sender.cpp
  src/core/at_protocol/deadman.cpp
  src/core/at_protocol/controller_session.cpp
  src/core/at_protocol/session_monitor.cpp
  src/core/at_protocol/goal_runner.cpp)
target_link_libraries(cnc_bridge_at_protocol PUBLIC cnc_bridge_gcode)

if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_at_protocol
    test/unit/test_at_codec.cpp
    test/unit/test_at_sequencer.cpp
    test/unit/test_at_planner.cpp
    test/unit/test_at_program_path.cpp
    test/unit/test_at_sender_realtime.cpp
    test/unit/test_at_sender.cpp
    test/unit/test_at_deadman.cpp
    test/unit/test_at_controller_session.cpp)
  target_link_libraries(test_at_protocol cnc_bridge_at_protocol)
endif()

# The simulated controller (a peer model, not shipped in the protocol library) and its program.
cnc_sim_library(cnc_bridge_at_protocol_sim src/sim/at_protocol/sim_controller.cpp)
target_link_libraries(cnc_bridge_at_protocol_sim PUBLIC cnc_bridge_at_protocol cnc_bridge_testing)
cnc_tool(sim_at_controller src/sim/sim_at_controller.cpp)
target_link_libraries(sim_at_controller cnc_bridge_at_protocol_sim cnc_bridge_testing)
cnc_tool(at_stream_bench bench/at_controller/at_stream_bench.cpp)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  # cnc_plan's setpoints against the node's planning path (planProgram, Trajectory, TrajectoryStream).
  cnc_core_gtest(test_cnc_plan test/unit/test_cnc_plan.cpp)
  target_link_libraries(test_cnc_plan cnc_bridge_at_protocol)
  add_dependencies(test_cnc_plan cnc_plan)
  target_compile_definitions(test_cnc_plan PRIVATE CNC_PLAN="$<TARGET_FILE:cnc_plan>"
                             CNC_BRIDGE_FIXTURE_DIR="${PROJECT_SOURCE_DIR}/test/data/gcode")
endif()

if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(at_controller_node src/ros/nodes/at_controller_node.cpp src/ros/nodes/at_controller_params.cpp
           src/ros/nodes/at_controller_goal.cpp)
  target_link_libraries(at_controller_node cnc_bridge_at_protocol cnc_bridge_gcode)
endif()

if(NOT CNC_BRIDGE_CORE_ONLY AND CATKIN_ENABLE_TESTING)
  find_package(rostest REQUIRED)
  foreach(test at_controller at_controller_disabled at_controller_link)
    add_rostest_gtest(test_${test} test/rostest/${test}.test test/rostest/test_${test}.cpp)
    target_link_libraries(test_${test} ${catkin_LIBRARIES})
    add_dependencies(test_${test} at_controller_node sim_at_controller ${PROJECT_NAME}_generate_messages_cpp)
  endforeach()
  # The node's setpoints against cnc_plan's dry run of the same program, trapezoid and S-curve.
  add_dependencies(test_at_controller cnc_plan)
  add_rostest(test/rostest/at_controller_scurve.test DEPENDENCIES test_at_controller)
  target_compile_definitions(test_at_controller PRIVATE CNC_PLAN="$<TARGET_FILE:cnc_plan>"
                             CNC_BRIDGE_AT_PROGRAMS="${PROJECT_SOURCE_DIR}/test/data/at_controller")
endif()

cnc_fuzz_target(fuzz_at_report test/fuzz/fuzz_at_report.cpp)
cnc_fuzz_target(fuzz_at_command test/fuzz/fuzz_at_command.cpp)
