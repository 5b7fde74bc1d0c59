# What `cmake --install <build> --prefix P` puts in place, and the CMake package a consumer
# finds with find_package(desplat CONFIG REQUIRED) (docs/ARCHITECTURE.md, "Using desplat as a
# library"; examples/consumer/ uses it, the ctest test install_consumer builds it):
#   P/bin/desplat_*                          the apps (apps/CMakeLists.txt installs them)
#   P/include/desplat/<layer>/*.hpp          the public headers (no private header of src/)
#   P/lib/libdesplat-<layer>.a               one static library per layer
#   P/lib/cmake/desplat/desplatConfig.cmake  + desplatConfigVersion.cmake, desplatTargets*.cmake
# The imported targets are desplat::<layer> (desplat::core … desplat::jobs); each links the
# layer beneath it, so linking desplat::jobs brings the whole library.
include(CMakePackageConfigHelpers)

set(DESPLAT_CMAKE_PACKAGE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/desplat)
get_property(desplat_layer_targets GLOBAL PROPERTY DESPLAT_LAYER_TARGETS)

install(TARGETS ${desplat_layer_targets} EXPORT desplatTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/include/desplat DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        FILES_MATCHING PATTERN "*.hpp")
install(EXPORT desplatTargets NAMESPACE desplat:: DESTINATION ${DESPLAT_CMAKE_PACKAGE_DIR})

configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/desplatConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/desplatConfig.cmake
                              INSTALL_DESTINATION ${DESPLAT_CMAKE_PACKAGE_DIR})
# 0.x: a new minor version may change the API, so only the same minor version is compatible.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/desplatConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/desplatConfig.cmake ${PROJECT_BINARY_DIR}/desplatConfigVersion.cmake
        DESTINATION ${DESPLAT_CMAKE_PACKAGE_DIR})
