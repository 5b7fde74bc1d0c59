# The installed library is usable from outside: installs this build into a fresh prefix,
# configures and builds examples/consumer against it (find_package(desplat)) and runs it,
# which trains a few steps on a tiny synthetic scene and checks the outputs.
#   cmake -DBUILD_DIR=<desplat build> -DSOURCE_DIR=<desplat source> -DWORK_DIR=<scratch>
#         -DCXX_COMPILER=<c++> -DGENERATOR=<cmake generator> -P tests/install_consumer.cmake
# The consumer sees the installed prefix and the system only: CMAKE_PREFIX_PATH is the prefix,
# and nothing of the source tree or the build tree is on its include path.
cmake_minimum_required(VERSION 3.22)
foreach(var BUILD_DIR SOURCE_DIR WORK_DIR CXX_COMPILER GENERATOR)
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

set(prefix ${WORK_DIR}/prefix)
file(REMOVE_RECURSE ${WORK_DIR})
run("cmake --install" ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix})
foreach(file lib/cmake/desplat/desplatConfig.cmake lib/cmake/desplat/desplatConfigVersion.cmake
             lib/cmake/desplat/desplatTargets.cmake include/desplat/jobs/training_run.hpp
             lib/libdesplat-jobs.a bin/desplat_train)
  if(NOT EXISTS ${prefix}/${file})
    message(FATAL_ERROR "install_consumer: the install has no ${file}")
  endif()
endforeach()

run("configuring the consumer" ${CMAKE_COMMAND} -S ${SOURCE_DIR}/examples/consumer -B ${WORK_DIR}/build
    -G ${GENERATOR} -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=${CXX_COMPILER}
    -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF)
run("building the consumer" ${CMAKE_COMMAND} --build ${WORK_DIR}/build)
run("running the consumer" ${WORK_DIR}/build/train_tiny_scene ${WORK_DIR}/run)
