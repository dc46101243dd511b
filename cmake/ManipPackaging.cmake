# The Debian side of the install (docs/install.md), included from the install
# section of the top-level CMakeLists.txt: manual pages generated from the
# programs' own --help/--version (help2man, cmake/manpage.sh), the Debian changelog, and the
# maintainer contact. Nothing here changes how the build tree runs.

# ---- the maintainer contact (Debian's Maintainer field and the changelog's
# trailer line). The default is a placeholder under the reserved .invalid
# domain (RFC 2606): lintian accepts its form, and no mail can ever reach it.
# A lab sets its own when it builds the package it installs.
set(MANIP_PACKAGE_CONTACT "manip lab build <manip-build@lab.invalid>" CACHE STRING
    "Maintainer of the .deb, 'Name <address>' (set this for your lab's build; docs/install.md)")
# Debian revision of the package (version <project version>-<revision>): a
# package built from upstream sources by CPack is not a native Debian package.
set(MANIP_DEBIAN_REVISION 1 CACHE STRING "Debian revision of the .deb (bump when repackaging the same version)")

# ---- manual pages: one per installed program, share/man/man1/<app>.1.gz,
# from the program's --help and --version (cmake/manpage.sh). AUTO: when
# help2man is found (Debian's help2man; scripts/setup.sh installs it) and the
# programs can run on this machine (not cross-compiled, not instrumented).
set(MANIP_MAN AUTO CACHE STRING "Generate and install manual pages with help2man: AUTO, ON or OFF")
set_property(CACHE MANIP_MAN PROPERTY STRINGS AUTO ON OFF)
find_program(HELP2MAN_EXECUTABLE help2man)
find_program(GZIP_EXECUTABLE gzip)
set(_manip_man OFF)
if(MANIP_MAN STREQUAL "AUTO")
  if(HELP2MAN_EXECUTABLE AND GZIP_EXECUTABLE AND NOT CMAKE_CROSSCOMPILING AND NOT MANIP_SANITIZE)
    set(_manip_man ON)
  endif()
elseif(MANIP_MAN)
  if(NOT (HELP2MAN_EXECUTABLE AND GZIP_EXECUTABLE))
    message(FATAL_ERROR "MANIP_MAN=ON needs help2man and gzip (apt-get install help2man)")
  endif()
  set(_manip_man ON)
endif()
# What was decided, for tests/install/deb_install.sh (it requires the pages when ON).
set(MANIP_MAN_PAGES ${_manip_man} CACHE INTERNAL "manual pages generated (resolved MANIP_MAN)")
if(_manip_man)
  set(_man_dir ${CMAKE_BINARY_DIR}/man)
  file(MAKE_DIRECTORY ${_man_dir})
  set(_pages)
  file(GLOB _app_srcs CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/apps/*.cpp)
  foreach(src ${_app_srcs})
    get_filename_component(app ${src} NAME_WE)
    set(tgt ${app})
    if(TARGET ${app}_app)
      set(tgt ${app}_app)
    endif()
    add_custom_command(
      OUTPUT ${_man_dir}/${app}.1.gz
      COMMAND sh ${CMAKE_SOURCE_DIR}/cmake/manpage.sh ${HELP2MAN_EXECUTABLE} $<TARGET_FILE_DIR:${tgt}> ${app}
              ${PROJECT_VERSION} ${_man_dir}/${app}.1.gz
      DEPENDS ${tgt} ${CMAKE_SOURCE_DIR}/cmake/manpage.sh
      COMMENT "help2man: ${app}.1"
      VERBATIM)
    list(APPEND _pages ${_man_dir}/${app}.1.gz)
  endforeach()
  add_custom_target(manip_man ALL DEPENDS ${_pages})
  install(FILES ${_pages} DESTINATION ${CMAKE_INSTALL_MANDIR}/man1)
else()
  message(STATUS "manual pages: off (MANIP_MAN=${MANIP_MAN}; help2man: ${HELP2MAN_EXECUTABLE})")
endif()

# ---- the Debian changelog: /usr/share/doc/manip/changelog.Debian.gz (Debian
# policy 12.7), one entry for this version, dated SOURCE_DATE_EPOCH when set
# (reproducible builds), otherwise when CMake configured the tree.
string(TIMESTAMP MANIP_CHANGELOG_DATE "%a, %d %b %Y %H:%M:%S +0000" UTC)
set(MANIP_DEBIAN_VERSION ${PROJECT_VERSION}-${MANIP_DEBIAN_REVISION})
configure_file(${CMAKE_SOURCE_DIR}/packaging/debian/changelog.in ${CMAKE_BINARY_DIR}/packaging/changelog.Debian @ONLY)
if(GZIP_EXECUTABLE)
  execute_process(COMMAND ${GZIP_EXECUTABLE} -9nc ${CMAKE_BINARY_DIR}/packaging/changelog.Debian
                  OUTPUT_FILE ${CMAKE_BINARY_DIR}/packaging/changelog.Debian.gz RESULT_VARIABLE _rc)
  if(NOT _rc EQUAL 0)
    message(FATAL_ERROR "gzip changelog.Debian: exit ${_rc}")
  endif()
  install(FILES ${CMAKE_BINARY_DIR}/packaging/changelog.Debian.gz DESTINATION ${CMAKE_INSTALL_DOCDIR})
else()
  install(FILES ${CMAKE_BINARY_DIR}/packaging/changelog.Debian DESTINATION ${CMAKE_INSTALL_DOCDIR})
endif()

# lintian overrides (packaging/debian/lintian-overrides: each with its reason).
install(FILES ${CMAKE_SOURCE_DIR}/packaging/debian/lintian-overrides DESTINATION ${CMAKE_INSTALL_DATADIR}/lintian/overrides
        RENAME manip)

# ---- everything `cmake --install` and cpack install, as one target
# (CMAKE_SKIP_INSTALL_ALL_DEPENDENCY: they build nothing themselves):
#   ninja -C build manip_installable && (cd build && cpack -G DEB)
add_custom_target(manip_installable)
file(GLOB _app_srcs CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/apps/*.cpp)
foreach(src ${_app_srcs})
  get_filename_component(app ${src} NAME_WE)
  if(TARGET ${app}_app)
    add_dependencies(manip_installable ${app}_app)
  else()
    add_dependencies(manip_installable ${app})
  endif()
endforeach()
add_dependencies(manip_installable manip_lcmtypes_gen)
foreach(t manip_lcmtypes_jar manip_man)
  if(TARGET ${t})
    add_dependencies(manip_installable ${t})
  endif()
endforeach()
