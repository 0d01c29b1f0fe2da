# DNC drip-feed and program backup (docs/protocols/drip_feed.md): the streaming sender, the backup
# receiver, the simulated control (used by sim_haas_serial's drip and punch modes), program requests
# from the control, their tests, and dnc_node.
cnc_core_module(cnc_bridge_drip
  src/core/dnc/dnc_codes.cpp
  src/core/dnc/nc_program.cpp
  src/core/dnc/drip_feed.cpp
  src/core/dnc/backup.cpp
  src/core/dnc/commanded_position.cpp)
target_link_libraries(cnc_bridge_drip PUBLIC cnc_bridge_gcode)  # the block lexer of nc_program.cpp, the parser of commanded_position.cpp
target_link_libraries(cnc_bridge_drip PUBLIC cnc_bridge_programs)  # the program header the feed checks

# The simulated control, shared by sim_haas_serial and the unit tests that run it in-process.
add_library(cnc_bridge_dnc_sim STATIC
  src/sim/haas_serial/dnc_drip_control.cpp
  src/sim/haas_serial/dnc_punch.cpp)
target_include_directories(cnc_bridge_dnc_sim PUBLIC ${PROJECT_SOURCE_DIR}/src/sim/haas_serial)
target_link_libraries(cnc_bridge_dnc_sim PUBLIC cnc_bridge_drip)

if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_drip_program test/unit/test_drip_program.cpp)
  target_link_libraries(test_drip_program cnc_bridge_drip)
  cnc_core_gtest(test_drip_feed test/unit/test_drip_feed.cpp)
  target_link_libraries(test_drip_feed cnc_bridge_dnc_sim)
  cnc_core_gtest(test_backup test/unit/test_backup.cpp)
  target_link_libraries(test_backup cnc_bridge_dnc_sim)
  cnc_core_gtest(test_commanded_position test/unit/test_commanded_position.cpp)
  target_link_libraries(test_commanded_position cnc_bridge_drip)
endif()

cnc_fuzz_target(fuzz_dnc_backup test/fuzz/fuzz_dnc_backup.cpp)
cnc_fuzz_target(fuzz_dnc_program test/fuzz/fuzz_dnc_program.cpp)

# Benchmark driver (bench/dnc/run_bench.sh runs it from a build directory).
cnc_tool(dnc_drip_bench bench/dnc/drip_bench.cpp)
target_link_libraries(dnc_drip_bench cnc_bridge_dnc_sim cnc_bridge_testing)

# dnc_node: XModem send and receive, drip and backup, program requests from the control.
if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(dnc_node
    src/ros/nodes/dnc_node.cpp
    src/ros/nodes/dnc_params.cpp
    src/ros/nodes/dnc_transfer_action.cpp
    src/ros/nodes/dnc_drip_handlers.cpp
    src/ros/nodes/dnc_commanded_position.cpp)
  target_link_libraries(dnc_node cnc_bridge_xmodem cnc_bridge_programs cnc_bridge_drip cnc_bridge_requests)
endif()

if(NOT CNC_BRIDGE_CORE_ONLY AND CATKIN_ENABLE_TESTING)
  find_package(rostest REQUIRED)  # the top level finds it only after the fragments
  add_rostest_gtest(test_dnc_drip test/rostest/dnc_drip.test test/rostest/test_dnc_drip.cpp)
  target_link_libraries(test_dnc_drip ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
  add_dependencies(test_dnc_drip dnc_node sim_haas_serial ${PROJECT_NAME}_generate_messages_cpp)
  # The feed breaking off: node death (respawn) and link loss, seen from the control's side.
  add_rostest_gtest(test_dnc_drip_link test/rostest/dnc_drip_link.test test/rostest/test_dnc_drip_link.cpp)
  target_link_libraries(test_dnc_drip_link ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
  add_dependencies(test_dnc_drip_link dnc_node sim_haas_serial ${PROJECT_NAME}_generate_messages_cpp)
endif()


# Program requests punched by the control (docs/dnc_node.md, "Program requests from the control"):
# the idle listener reads a punch with the XModem receiver or the backup parser and answers; and
# dnc_node's ROS-free transfer rules (one transfer at a time, the files a transfer may touch, the
# archive, the counters) and its transfer session (the link, the run of a transfer, the XModem,
# drip and backup protocols, the program requests served).
cnc_core_module(cnc_bridge_requests
  src/core/dnc/program_requests.cpp
  src/core/dnc/transfer_gate.cpp
  src/core/dnc/transfer_rules.cpp
  src/core/dnc/transfer_session.cpp
  src/core/dnc/transfer_session_requests.cpp
  src/core/dnc/drip_protocols.cpp)
target_link_libraries(cnc_bridge_requests PUBLIC cnc_bridge_xmodem cnc_bridge_drip cnc_bridge_programs)
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  # A control played by lrzsz sx/rx (XModem) and by the test (text) on a pty pair.
  cnc_core_gtest(test_program_requests test/unit/test_program_requests.cpp test/unit/test_transfer_rules.cpp)
  if(TARGET test_program_requests)
    target_link_libraries(test_program_requests cnc_bridge_requests yaml-cpp)
    target_compile_definitions(test_program_requests PRIVATE XMODEM_TEST_DATA="${PROJECT_SOURCE_DIR}/test/data/xmodem"
                                                             SIM_HAAS_SERIAL="$<TARGET_FILE:sim_haas_serial>")
    add_dependencies(test_program_requests sim_haas_serial)
  endif()
  # dnc_node's transfer session without ROS: XModem, drip and backup against a control on a pty.
  cnc_core_gtest(test_transfer_session test/unit/test_transfer_session.cpp)
  if(TARGET test_transfer_session)
    target_link_libraries(test_transfer_session cnc_bridge_requests)
  endif()
endif()
if(NOT CNC_BRIDGE_CORE_ONLY AND CATKIN_ENABLE_TESTING)
  # dnc_node ~requests against python3-xmodem and lrzsz on a socat pty pair.
  add_rostest_gtest(test_dnc_requests test/rostest/dnc_requests.test test/rostest/test_dnc_requests.cpp)
  target_link_libraries(test_dnc_requests cnc_bridge_programs ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
  add_dependencies(test_dnc_requests dnc_node ${PROJECT_NAME}_generate_messages_cpp)
endif()
