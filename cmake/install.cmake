# Installing raypack: `cmake --install build/release --prefix P` (or `make install PREFIX=P`).
#
# What goes where, and why:
#   include/raypack.h, raypack_io.h, raypack_render.h     the public headers (every include/*.h)
#   lib/libraypack.so.0 (core, versioned soname)          what embedders link: only rp_ symbols
#   lib/libraypack_static.a (core)                         the same, for static linking
#   lib/libraypack_io.so.0, lib/libraypack_render.so.0     loaders + image files, renderer: so an
#       out-of-tree program can load a scene file (every format, assimp's too) and render it. Built
#       from the objects of the in-tree static libraries (which stay what the CLI and the tests
#       link), hidden visibility, rp_ symbols only; zlib, libarchive and assimp stay private.
#       They are not installed as static archives: those would drag their private dependencies into
#       every consumer's link line.
#   bin/raypack, share/man/man1/raypack.1 (from the commands' --help), share/doc/raypack/
#   lib/pkgconfig/raypack.pc (core), raypack-render.pc (io + render, Requires: raypack)
#   lib/cmake/raypack/raypackConfig.cmake + version file: find_package(raypack CONFIG) gives
#       raypack::raypack, raypack::raypack_static, raypack::io and raypack::render.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set_target_properties(raypack PROPERTIES VERSION ${PROJECT_VERSION} SOVERSION ${PROJECT_VERSION_MAJOR})

set(RP_INSTALL_TARGETS raypack raypack_static)
# io and render as shared libraries, from the static libraries' objects (compiled once).
if(TARGET raypack_io)
  target_compile_options(raypack_io PRIVATE -fvisibility=hidden)
  add_library(raypack_io_shared SHARED $<TARGET_OBJECTS:raypack_io>)
  set_target_properties(raypack_io_shared PROPERTIES OUTPUT_NAME raypack_io EXPORT_NAME io
    VERSION ${PROJECT_VERSION} SOVERSION ${PROJECT_VERSION_MAJOR})
  target_include_directories(raypack_io_shared PUBLIC $<BUILD_INTERFACE:${CMAKE_SOURCE_DIR}/include>
    $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  # the static library's own (private) dependencies: zlib, libarchive, assimp
  target_link_libraries(raypack_io_shared PRIVATE $<TARGET_PROPERTY:raypack_io,LINK_LIBRARIES>)
  list(APPEND RP_INSTALL_TARGETS raypack_io_shared)
endif()
if(TARGET raypack_render AND TARGET raypack_io_shared)
  target_compile_options(raypack_render PRIVATE -fvisibility=hidden)
  add_library(raypack_render_shared SHARED $<TARGET_OBJECTS:raypack_render>)
  set_target_properties(raypack_render_shared PROPERTIES OUTPUT_NAME raypack_render EXPORT_NAME render
    VERSION ${PROJECT_VERSION} SOVERSION ${PROJECT_VERSION_MAJOR})
  target_link_libraries(raypack_render_shared PUBLIC raypack raypack_io_shared PRIVATE m)
  list(APPEND RP_INSTALL_TARGETS raypack_render_shared)
endif()
# Installed programs and libraries find their siblings in lib/ wherever the prefix is.
set_target_properties(${RP_INSTALL_TARGETS} PROPERTIES INSTALL_RPATH "$ORIGIN")

install(TARGETS ${RP_INSTALL_TARGETS} EXPORT raypackTargets
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
file(GLOB RP_PUBLIC_HEADERS CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/include/*.h)
install(FILES ${RP_PUBLIC_HEADERS} DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
if(TARGET raypack_cli)
  install(TARGETS raypack_cli RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
  # The man page is the commands' own --help text, so it cannot drift from them.
  set(RP_MAN ${CMAKE_BINARY_DIR}/raypack.1)
  add_custom_command(OUTPUT ${RP_MAN}
    COMMAND ${CMAKE_COMMAND} -DRAYPACK=$<TARGET_FILE:raypack_cli> -DOUT=${RP_MAN}
            -DVERSION=${PROJECT_VERSION} -P ${CMAKE_SOURCE_DIR}/cmake/man_page.cmake
    DEPENDS raypack_cli ${CMAKE_SOURCE_DIR}/cmake/man_page.cmake VERBATIM)
  add_custom_target(raypack_man ALL DEPENDS ${RP_MAN})
  install(FILES ${RP_MAN} DESTINATION ${CMAKE_INSTALL_MANDIR}/man1)
endif()
install(FILES ${CMAKE_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})

# CMake package
install(EXPORT raypackTargets NAMESPACE raypack:: DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/raypack)
configure_package_config_file(${CMAKE_SOURCE_DIR}/cmake/raypackConfig.cmake.in
  ${CMAKE_BINARY_DIR}/raypackConfig.cmake INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/raypack)
# 0.x: minor versions may break the API, so a request for 0.1 accepts 0.1.x only.
write_basic_package_version_file(${CMAKE_BINARY_DIR}/raypackConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/raypackConfig.cmake ${CMAKE_BINARY_DIR}/raypackConfigVersion.cmake
  DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/raypack)

# pkg-config: paths relative to the .pc file's prefix, set at install time (--prefix may differ
# from CMAKE_INSTALL_PREFIX), so the files are written by an install script.
install(CODE "
  set(RP_PREFIX \"\${CMAKE_INSTALL_PREFIX}\")
  set(RP_LIBDIR \"${CMAKE_INSTALL_LIBDIR}\")
  set(RP_INCLUDEDIR \"${CMAKE_INSTALL_INCLUDEDIR}\")
  set(RP_VERSION \"${PROJECT_VERSION}\")
  foreach(pc raypack raypack-render)
    configure_file(\"${CMAKE_SOURCE_DIR}/cmake/\${pc}.pc.in\" \"${CMAKE_BINARY_DIR}/pc/\${pc}.pc\" @ONLY)
    file(INSTALL \"${CMAKE_BINARY_DIR}/pc/\${pc}.pc\" DESTINATION \"\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_LIBDIR}/pkgconfig\")
  endforeach()
")
