# The installed library is usable from outside: installs this build into a fresh prefix,
# configures and builds examples/consumer against it (find_package(desplat)) and runs it,
# which trains a few steps on a tiny synthetic scene and checks the outputs.
#   cmake -DBUILD_DIR=<desplat build> -DSOURCE_DIR=<desplat source> -DWORK_DIR=<scratch>
#         -DCXX_COMPILER=<c++> -DGENERATOR=<cmake generator> -DLIBDIR=… -DBINDIR=… -DINCLUDEDIR=…
#         (GNUInstallDirs' relative folders) [-DBUILD_TYPE=… -DCXX_FLAGS=… -DLINKER_FLAGS=…]
#         -P tests/install_consumer.cmake
# The consumer sees the installed prefix and the system only: CMAKE_PREFIX_PATH is the prefix,
# and nothing of the source tree or the build tree is on its include path. It gets the build's
# compiler and global flags (CMAKE_CXX_FLAGS, not desplat's own options), since a sanitizer
# build's libraries need the sanitizer runtime where they are linked.
cmake_minimum_required(VERSION 3.22)
foreach(var BUILD_DIR SOURCE_DIR WORK_DIR CXX_COMPILER GENERATOR LIBDIR BINDIR INCLUDEDIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "install_consumer: pass -D${var}=…")
  endif()
endforeach()

function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE code)
  if(NOT code EQUAL 0)
    message(FATAL_ERROR "install_consumer: ${what} failed (exit ${code}): ${ARGN}")
  endif()
endfunction()

if(NOT BUILD_TYPE)
  set(BUILD_TYPE Release)
endif()
set(prefix ${WORK_DIR}/prefix)
file(REMOVE_RECURSE ${WORK_DIR})
run("cmake --install" ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix})
foreach(file ${LIBDIR}/cmake/desplat/desplatConfig.cmake ${LIBDIR}/cmake/desplat/desplatConfigVersion.cmake
             ${LIBDIR}/cmake/desplat/desplatTargets.cmake ${INCLUDEDIR}/desplat/jobs/training_run.hpp
             ${LIBDIR}/libdesplat-jobs.a ${BINDIR}/desplat_train ${BINDIR}/desplat_synth)
  if(NOT EXISTS ${prefix}/${file})
    message(FATAL_ERROR "install_consumer: the install has no ${file}")
  endif()
endforeach()
run("the installed desplat_train --help" ${prefix}/${BINDIR}/desplat_train --help OUTPUT_QUIET)

run("configuring the consumer" ${CMAKE_COMMAND} -S ${SOURCE_DIR}/examples/consumer -B ${WORK_DIR}/build
    -G ${GENERATOR} -DCMAKE_BUILD_TYPE=${BUILD_TYPE} -DCMAKE_CXX_COMPILER=${CXX_COMPILER}
    "-DCMAKE_CXX_FLAGS=${CXX_FLAGS}" "-DCMAKE_EXE_LINKER_FLAGS=${LINKER_FLAGS}"
    -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF)
run("building the consumer" ${CMAKE_COMMAND} --build ${WORK_DIR}/build)
run("running the consumer" ${WORK_DIR}/build/train_tiny_scene ${WORK_DIR}/run)
