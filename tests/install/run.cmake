# test_install: installs the build tree into a fresh prefix, then builds the out-of-tree consumer
# against it both ways (pkg-config, and find_package in a CMake project of its own), runs both on
# the given scenes, and checks the command and the man page. cmake -P with BUILD, SOURCE, WORK,
# SCENES (|-separated), CC and, for the Python package, PYTHON.
set(prefix ${WORK}/prefix)
string(REPLACE "|" ";" SCENES "${SCENES}") # |-separated: a ;-list does not survive add_test
file(REMOVE_RECURSE ${WORK})
file(MAKE_DIRECTORY ${WORK})
set(passed 0)
set(failed 0)
function(step name)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  if(rc EQUAL 0)
    math(EXPR p "${passed} + 1")
    set(passed ${p} PARENT_SCOPE)
    message("ok: ${name}")
  else()
    math(EXPR f "${failed} + 1")
    set(failed ${f} PARENT_SCOPE)
    message("FAIL: ${name} (exit ${rc})\n${out}")
  endif()
  set(last_out "${out}" PARENT_SCOPE)
endfunction()

step("cmake --install" ${CMAKE_COMMAND} --install ${BUILD} --prefix ${prefix})
foreach(f include/raypack.h include/raypack_io.h include/raypack_render.h lib/libraypack_static.a
          share/man/man1/raypack.1 lib/cmake/raypack/raypackConfigVersion.cmake)
  step("installed ${f}" ${CMAKE_COMMAND} -E cat ${prefix}/${f})
endforeach()
step("soname libraypack.so.0" readelf -d ${prefix}/lib/libraypack.so.0)
if(NOT last_out MATCHES "SONAME[^\n]*libraypack\\.so\\.0\\]")
  math(EXPR failed "${failed} + 1")
  message("FAIL: libraypack.so has no versioned soname")
endif()
step("raypack --version" ${prefix}/bin/raypack --version)
step("raypack render" ${prefix}/bin/raypack render --width 32 --height 32 -o ${WORK}/room.ppm)

# pkg-config: the compile line it gives, nothing else
set(ENV{PKG_CONFIG_PATH} ${prefix}/lib/pkgconfig)
execute_process(COMMAND pkg-config --cflags --libs raypack-render OUTPUT_VARIABLE pc_flags
  RESULT_VARIABLE pc_rc OUTPUT_STRIP_TRAILING_WHITESPACE)
separate_arguments(pc_flags UNIX_COMMAND "${pc_flags}")
message("pkg-config --cflags --libs raypack-render: ${pc_flags}")
step("pkg-config build" ${CC} -std=c11 -Wall -Werror ${SOURCE}/consumer.c -o ${WORK}/consumer_pc
     ${pc_flags} -lm -Wl,-rpath,${prefix}/lib)
step("pkg-config program" ${WORK}/consumer_pc ${SCENES})
message("${last_out}")

# find_package(raypack CONFIG)
step("find_package configure" ${CMAKE_COMMAND} -S ${SOURCE} -B ${WORK}/cmake_build
     -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_C_COMPILER=${CC} -DCMAKE_BUILD_TYPE=Release)
step("find_package build" ${CMAKE_COMMAND} --build ${WORK}/cmake_build)
step("find_package program" ${WORK}/cmake_build/consumer ${SCENES})
message("${last_out}")

# the Python package, built on the installed libraries (RAYPACK_PREFIX) instead of the build tree
if(PYTHON)
  file(COPY ${SOURCE}/../../python/ DESTINATION ${WORK}/python PATTERN tests EXCLUDE PATTERN build EXCLUDE)
  set(ENV{RAYPACK_PREFIX} ${prefix})
  step("pip install ./python on the prefix" ${PYTHON} -m pip install --no-build-isolation --no-index
       --no-deps --no-cache-dir --disable-pip-version-check --target ${WORK}/site ${WORK}/python)
  set(ENV{PYTHONPATH} ${WORK}/site)
  list(GET SCENES 0 first_scene)
  step("python: raypack.load and intersect" ${PYTHON} -c
       "import numpy as np, raypack; s = raypack.load('${first_scene}'); lo, hi = s.bounds; c = (lo + hi) / 2; \
h = s.intersect(np.array([c], np.float32), np.array([[0, 0, -1]], np.float32)); assert h['geom_id'][0] == 0, h")
endif()

message("${passed} passed, ${failed} failed")
if(failed GREATER 0)
  message(FATAL_ERROR "install test failed")
endif()
