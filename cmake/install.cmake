# `cmake --install build --prefix P`: the libraries, the public headers and lidefConfig.cmake (+ version file)
# exporting lidef::core, lidef::cage, lidef::explorer, lidef::analysis, lidef::opencl and lidef::compare.
# A program then needs `find_package(lidef CONFIG REQUIRED)` and `target_link_libraries(app lidef::core)`
# (examples/cpp/deform_and_certify). The CLI goes to bin/; the Python module has its own component.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(LIDEF_LIBRARIES lidef_core lidef_cage lidef_explorer lidef_analysis lidef_opencl lidef_compare)
set(LIDEF_EXPORT_NAMES core cage explorer analysis opencl compare)

# Position-independent code: the libraries are static, and the Python module (a shared object) and a user's
# own shared libraries link them. The objects the libraries take from OBJECT libraries need it too.
set_target_properties(${LIDEF_LIBRARIES} lidef_cgal lidef_cage_cgal lidef_tetgen PROPERTIES POSITION_INDEPENDENT_CODE ON)

foreach(target name IN ZIP_LISTS LIDEF_LIBRARIES LIDEF_EXPORT_NAMES)
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${name})
  target_include_directories(${target} INTERFACE $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
endforeach()
# Eigen's vectorized code assumes the alignment of the instruction set it was compiled for: a program built
# without AVX that hands an Eigen matrix to a library built with it may crash. Programs using the installed
# libraries compile for the same instruction set (the build tree's own targets get it from lidef_warnings).
if(LIDEF_NATIVE)
  target_compile_options(lidef_core INTERFACE $<INSTALL_INTERFACE:-march=native -mno-avx512f>)
endif()

install(TARGETS ${LIDEF_LIBRARIES} lidef_warnings EXPORT lidefTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT development
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(TARGETS lidef lidef-compare RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT runtime)

# Public headers: the paper's concepts and the API, one include prefix per library (lidef/, lidef/analysis/,
# lidef/cage/, lidef/compare/, lidef/explorer/, lidef/opencl/). Implementation headers live in
# deform/internal/lidef/internal/ and are not installed; no public header includes them.
foreach(dir deform analysis explorer cage compare opencl)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${dir}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
          COMPONENT development FILES_MATCHING PATTERN "*.h")
endforeach()

set(LIDEF_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/lidef)
install(EXPORT lidefTargets NAMESPACE lidef:: DESTINATION ${LIDEF_CMAKE_DIR} COMPONENT development)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/lidefConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/lidefConfig.cmake INSTALL_DESTINATION ${LIDEF_CMAKE_DIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/lidefConfigVersion.cmake VERSION ${PROJECT_VERSION}
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/lidefConfig.cmake ${PROJECT_BINARY_DIR}/lidefConfigVersion.cmake
        DESTINATION ${LIDEF_CMAKE_DIR} COMPONENT development)
