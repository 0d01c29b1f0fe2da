# programs: what every wire shares about programs, without SMB. cnc_bridge_programs (program names
# and numbers, the protected range, the ProgramStore interface and the local store, archive,
# program requests and their server, fan-out, daily times and the daily timer, withdrawals,
# transfers and the transfer core dnc_node and share_node share), its unit tests and fuzz targets.
cnc_core_module(cnc_bridge_programs
  src/core/programs/program_name.cpp
  src/core/programs/program_store.cpp
  src/core/programs/archive.cpp
  src/core/programs/program_request.cpp
  src/core/programs/fan_out.cpp
  src/core/programs/daily_time.cpp
  src/core/programs/daily_timer.cpp
  src/core/programs/withdrawal.cpp
  src/core/programs/request_server.cpp
  src/core/programs/program_transfers.cpp
  src/core/programs/transfer_core.cpp)

if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_program_name test/unit/test_program_name.cpp test/unit/test_program_archive.cpp
  test/unit/test_program_request.cpp test/unit/test_fan_out.cpp test/unit/test_daily_time.cpp
  test/unit/test_daily_timer.cpp test/unit/test_withdrawal.cpp test/unit/test_request_server.cpp
  test/unit/test_program_transfers.cpp test/unit/test_transfer_core.cpp)
  target_link_libraries(test_program_name cnc_bridge_programs)
endif()

cnc_fuzz_target(fuzz_program_name test/fuzz/fuzz_program_name.cpp)
if(CNC_BRIDGE_FUZZ)
  target_link_libraries(fuzz_program_name cnc_bridge_programs)
endif()

cnc_fuzz_target(fuzz_program_request test/fuzz/fuzz_program_request.cpp)
if(CNC_BRIDGE_FUZZ)
  target_link_libraries(fuzz_program_request cnc_bridge_programs)
endif()
