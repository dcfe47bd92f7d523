# The installed layout (GNUInstallDirs) and the Debian package (CPack): binaries in bin/, scenes and the Cyclone
# configurations in share/ladder/, ladderd.toml in etc/ladder/ (/etc/ladder for the /usr prefix), the systemd
# units, the docs. scripts/package builds ladder_<version>_amd64.deb; docs/install.md says how to use it.
include(GNUInstallDirs)

# /etc for a /usr install (the Debian package), else relative, so that `cmake --install --prefix P` puts it in P.
if(CMAKE_INSTALL_PREFIX STREQUAL "/usr")
  set(LADDER_ETC_DIR /etc/ladder)
else()
  set(LADDER_ETC_DIR ${CMAKE_INSTALL_SYSCONFDIR}/ladder)
endif()
set(LADDER_ETC_FULL ${CMAKE_INSTALL_FULL_SYSCONFDIR}/ladder)

install(FILES ${PROJECT_SOURCE_DIR}/config/scenes/classic.toml ${PROJECT_SOURCE_DIR}/config/scenes/double-ripple.toml
              ${PROJECT_SOURCE_DIR}/config/scenes/free-chain.toml ${PROJECT_SOURCE_DIR}/config/scenes/long.toml
              ${PROJECT_SOURCE_DIR}/config/scenes/toy-1889.toml ${PROJECT_SOURCE_DIR}/config/scenes/tall.toml
              ${PROJECT_SOURCE_DIR}/config/scenes/tall-double-ripple.toml
        DESTINATION ${CMAKE_INSTALL_DATADIR}/ladder/scenes)
install(FILES ${PROJECT_SOURCE_DIR}/config/cyclonedds.xml ${PROJECT_SOURCE_DIR}/config/cyclonedds-network.xml
              ${PROJECT_SOURCE_DIR}/config/cyclonedds-docker.xml ${PROJECT_SOURCE_DIR}/msgs/ladder.idl
        DESTINATION ${CMAKE_INSTALL_DATADIR}/ladder)
# A client of your own: its source, to build against the IDL above (docs/server.md, "Your own client").
install(FILES ${PROJECT_SOURCE_DIR}/examples/c-client/ladder_client.c
              ${PROJECT_SOURCE_DIR}/examples/c-client/CMakeLists.txt
        DESTINATION ${CMAKE_INSTALL_DOCDIR}/examples/c-client)
install(CODE "set(LADDER_SOURCE_DIR \"${PROJECT_SOURCE_DIR}\")
set(LADDER_ETC_DIR \"${LADDER_ETC_DIR}\")
set(LADDER_DATADIR \"${CMAKE_INSTALL_DATADIR}\")")
install(SCRIPT ${PROJECT_SOURCE_DIR}/cmake/install_config.cmake)

# ladderd.service serves sim id "ladder"; ladderd@NAME.service serves sim id NAME.
foreach(unit ladderd ladderd@)
  if(unit STREQUAL "ladderd")
    set(LADDER_UNIT_ABOUT "One ladder, sim id \"ladder\"; for several, ladderd@NAME.service.")
    set(LADDER_UNIT_TITLE "")
    set(LADDER_UNIT_ARGS "")
    set(LADDER_UNIT_STATE "")
  else()
    set(LADDER_UNIT_ABOUT "One instance per ladder: ladderd@NAME serves sim id NAME, its logs in /var/lib/ladder/NAME.")
    set(LADDER_UNIT_TITLE ", sim id %i")
    set(LADDER_UNIT_ARGS " --sim-id %i")
    set(LADDER_UNIT_STATE "/%i")
  endif()
  configure_file(${PROJECT_SOURCE_DIR}/config/systemd/ladderd.service.in ${PROJECT_BINARY_DIR}/systemd/${unit}.service
                 @ONLY)
  install(FILES ${PROJECT_BINARY_DIR}/systemd/${unit}.service DESTINATION lib/systemd/system)
endforeach()
install(FILES ${PROJECT_SOURCE_DIR}/README.md ${PROJECT_SOURCE_DIR}/docs/install.md ${PROJECT_SOURCE_DIR}/docs/server.md
              ${PROJECT_SOURCE_DIR}/docs/network.md
        DESTINATION ${CMAKE_INSTALL_DOCDIR})

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME ladder)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_CONTACT "ladder maintainers <ladder@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "real-time physics server for a virtual Jacob's ladder, with its clients")
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # ladder_<version>_<arch>.deb
set(CPACK_DEBIAN_PACKAGE_SECTION science)
# The libraries' packages, from what the binaries link (dpkg-shlibdeps), and the viewer's font.
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_DEPENDS "fonts-dejavu-core")
file(WRITE ${PROJECT_BINARY_DIR}/debian/conffiles "/etc/ladder/ladderd.toml\n")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA ${PROJECT_BINARY_DIR}/debian/conffiles)
include(CPack)
