# Runs at install time (install(SCRIPT) in CMakeLists.txt): writes ladderd.toml into the configuration folder, its
# scenes_dir naming the installed scenes, so that an installed ladderd finds them from anywhere. The prefix is the
# one given at install time (cmake --install --prefix P, or CPack's), not the one configured.
if(IS_ABSOLUTE "${LADDER_ETC_DIR}")
  set(dir "$ENV{DESTDIR}${LADDER_ETC_DIR}")
else()
  set(dir "$ENV{DESTDIR}${CMAKE_INSTALL_PREFIX}/${LADDER_ETC_DIR}")
endif()
file(READ "${LADDER_SOURCE_DIR}/config/ladderd.toml" text)
string(REPLACE "scenes_dir = \"scenes\"" "scenes_dir = \"${CMAKE_INSTALL_PREFIX}/${LADDER_DATADIR}/ladder/scenes\""
       text "${text}")
if(NOT text MATCHES "/ladder/scenes\"")
  message(FATAL_ERROR "config/ladderd.toml has no line 'scenes_dir = \"scenes\"' to point at the installed scenes")
endif()
file(MAKE_DIRECTORY "${dir}")
file(WRITE "${dir}/ladderd.toml" "${text}")
message(STATUS "Installing: ${dir}/ladderd.toml")
list(APPEND CMAKE_INSTALL_MANIFEST_FILES "${dir}/ladderd.toml")
