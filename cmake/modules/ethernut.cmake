# ethernut: the qCNC 5-float opcode protocol (codec, client session, settings file, simulated
# board), sim_ethernut, and ethernut_node (job streaming and preview; uses cnc_bridge_gcode).
cnc_core_module(cnc_bridge_ethernut
  src/core/ethernut/protocol.cpp
  src/core/ethernut/client.cpp
  src/core/ethernut/settings.cpp
  src/core/ethernut/job.cpp
  src/core/ethernut/job_streamer.cpp
  src/core/ethernut/board_session.cpp
  src/core/ethernut/debug_channel.cpp)
target_link_libraries(cnc_bridge_ethernut PUBLIC cnc_bridge_gcode)  # a job's G-code program
# The simulated board (a peer model, not shipped in the protocol library): sim_ethernut and tests.
cnc_sim_library(cnc_bridge_ethernut_sim src/sim/ethernut/board.cpp src/sim/ethernut/debug_port.cpp)
target_link_libraries(cnc_bridge_ethernut_sim PUBLIC cnc_bridge_ethernut)
cnc_tool(sim_ethernut src/sim/sim_ethernut.cpp)
target_link_libraries(sim_ethernut cnc_bridge_ethernut_sim cnc_bridge_testing)
cnc_tool(bench_ethernut bench/ethernut/bench_ethernut.cpp)
target_link_libraries(bench_ethernut cnc_bridge_ethernut)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_ethernut test/unit/test_ethernut_codec.cpp test/unit/test_ethernut_client.cpp
                 test/unit/test_ethernut_job.cpp test/unit/test_ethernut_streamer.cpp
                 test/unit/test_ethernut_session.cpp test/unit/test_ethernut_debug.cpp)
  target_link_libraries(test_ethernut cnc_bridge_ethernut_sim)
  target_compile_definitions(test_ethernut PRIVATE CNC_BRIDGE_FIXTURE_DIR="${PROJECT_SOURCE_DIR}/test/data/gcode")
endif()
cnc_fuzz_target(fuzz_ethernut_stream test/fuzz/fuzz_ethernut_stream.cpp)
if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(ethernut_node src/ros/nodes/ethernut_node.cpp src/ros/nodes/ethernut_params.cpp src/ros/nodes/ethernut_services.cpp
           src/ros/nodes/ethernut_jobs.cpp)
  target_link_libraries(ethernut_node cnc_bridge_ethernut cnc_bridge_gcode)
  if(CATKIN_ENABLE_TESTING)
    find_package(rostest REQUIRED)
    add_rostest_gtest(test_ethernut_node test/rostest/ethernut_node.test test/rostest/test_ethernut_node.cpp)
    target_link_libraries(test_ethernut_node ${catkin_LIBRARIES} cnc_bridge_gcode)
    add_dependencies(test_ethernut_node ethernut_node sim_ethernut static_frame_node ${PROJECT_NAME}_generate_messages_cpp)
    add_rostest(test/rostest/ethernut_link.test DEPENDENCIES test_ethernut_node)
    add_rostest(test/rostest/ethernut_node_death.test DEPENDENCIES test_ethernut_node)
  endif()
endif()
