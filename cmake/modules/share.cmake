# share module: programs over Ethernet. cnc_bridge_share (the SMB store on Samba's libsmbclient,
# on cnc_bridge_programs of programs.cmake; share_node's settings and what its services decide),
# its tests, its part of cnc_dnc, and share_node.
find_path(SMBCLIENT_INCLUDE_DIR libsmbclient.h PATH_SUFFIXES samba-4.0)
find_library(SMBCLIENT_LIBRARY smbclient)
if(NOT SMBCLIENT_INCLUDE_DIR OR NOT SMBCLIENT_LIBRARY)
  message(FATAL_ERROR "libsmbclient not found: install the Debian package libsmbclient-dev")
endif()
cnc_core_module(cnc_bridge_share src/core/share/smb_store.cpp src/core/share/share_settings.cpp src/core/share/share_service.cpp
  src/core/share/hybrid_share.cpp)
target_include_directories(cnc_bridge_share PRIVATE ${SMBCLIENT_INCLUDE_DIR})
target_link_libraries(cnc_bridge_share PUBLIC cnc_bridge_programs ${SMBCLIENT_LIBRARY})

if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  # Against a real Samba server (smbd started by the test on a free loopback port).
  cnc_core_gtest(test_smb_store test/unit/test_smb_store.cpp)
  target_link_libraries(test_smb_store cnc_bridge_share)
  target_compile_definitions(test_smb_store PRIVATE
                             SERVED_SHARE_CONF="${PROJECT_SOURCE_DIR}/config/share/served_share.smb.conf")
  # The hybrid share: the drop folder and the collection, on local folders and a real Samba share.
  cnc_core_gtest(test_hybrid_share test/unit/test_hybrid_share.cpp)
  target_link_libraries(test_hybrid_share cnc_bridge_share)
  # share_node's settings and decisions, on local folders (no server).
  cnc_core_gtest(test_share_core test/unit/test_share_settings.cpp test/unit/test_share_service.cpp)
  target_link_libraries(test_share_core cnc_bridge_share)
endif()

# cnc_dnc send/receive --share and cnc_dnc list (cmake/modules/tools.cmake), against smbd.
if(CATKIN_ENABLE_TESTING OR CNC_BRIDGE_CORE_ONLY)
  cnc_core_gtest(test_share_cli test/unit/test_share_cli.cpp)
  if(TARGET test_share_cli)
    target_compile_definitions(test_share_cli PRIVATE CNC_DNC="$<TARGET_FILE:cnc_dnc>"
                               LSAN_SUPPRESSIONS="${PROJECT_SOURCE_DIR}/test/unit/lsan_libsmbclient.supp")
    target_link_libraries(test_share_cli cnc_bridge_programs)
    add_dependencies(test_share_cli cnc_dnc)
  endif()
endif()

if(NOT CNC_BRIDGE_CORE_ONLY)
  cnc_node(share_node src/ros/nodes/share_node.cpp src/ros/nodes/share_params.cpp src/ros/nodes/share_services.cpp
           src/ros/nodes/share_hub.cpp)
  target_link_libraries(share_node cnc_bridge_share)
  if(CATKIN_ENABLE_TESTING)
    # The real share_node against a real smbd, both started by the test (the server's port is free
    # only at run time).
    add_rostest_gtest(test_share_node test/rostest/share_node.test test/rostest/test_share_node.cpp)
    target_link_libraries(test_share_node ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
    target_include_directories(test_share_node PRIVATE ${PROJECT_SOURCE_DIR}/test/unit)
    add_dependencies(test_share_node share_node ${PROJECT_NAME}_generate_messages_cpp)
    # Two share_nodes on local folders, started by the test: ~publish_to_machines.
    add_rostest_gtest(test_share_fan_out test/rostest/share_fan_out.test test/rostest/test_share_fan_out.cpp)
    target_link_libraries(test_share_fan_out ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
    target_include_directories(test_share_fan_out PRIVATE ${PROJECT_SOURCE_DIR}/test/unit)
    target_compile_definitions(test_share_fan_out PRIVATE SHARE_NODE="$<TARGET_FILE:share_node>")
    add_dependencies(test_share_fan_out share_node ${PROJECT_NAME}_generate_messages_cpp)
  endif()
endif()
