# ctest Examples.InstalledPackageBuildsAndRuns (cmake -P): installs lidef into a fresh prefix, builds
# examples/cpp/deform_and_certify and the tutorial's C++ program (the ```cpp blocks of docs/tutorial.md, in
# order) against it as a user would (find_package(lidef CONFIG REQUIRED)), and runs both: each must print its
# "certified" line and exit 0.
#   -DBUILD_DIR= -DSOURCE_DIR= -DWORK_DIR= -DGENERATOR= [-DCCACHE=]
foreach(v BUILD_DIR SOURCE_DIR WORK_DIR GENERATOR)
  if(NOT DEFINED ${v})
    message(FATAL_ERROR "install_and_run.cmake: -D${v}=... missing")
  endif()
endforeach()

function(run what)
  cmake_parse_arguments(R "" "WORKING_DIRECTORY;EXPECT" "COMMAND" ${ARGN})
  if(NOT R_WORKING_DIRECTORY)
    set(R_WORKING_DIRECTORY ${WORK_DIR})
  endif()
  execute_process(COMMAND ${R_COMMAND} WORKING_DIRECTORY ${R_WORKING_DIRECTORY} RESULT_VARIABLE rc
                  OUTPUT_VARIABLE out ERROR_VARIABLE err)
  message(STATUS "${what}: exit ${rc}")
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (exit ${rc}):\n${out}\n${err}")
  endif()
  if(R_EXPECT AND NOT out MATCHES "${R_EXPECT}")
    message(FATAL_ERROR "${what}: output does not match '${R_EXPECT}':\n${out}\n${err}")
  endif()
  message(STATUS "${out}")
endfunction()

# The same folders every run (a fresh install each time), so that ccache recognizes the compilations.
file(REMOVE_RECURSE ${WORK_DIR})
file(MAKE_DIRECTORY ${WORK_DIR})
set(PREFIX ${WORK_DIR}/prefix)
run("install" COMMAND ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${PREFIX} --component development)
if(NOT EXISTS ${PREFIX}/lib/cmake/lidef/lidefConfig.cmake OR NOT EXISTS ${PREFIX}/include/lidef/lidef.h)
  message(FATAL_ERROR "install: lidefConfig.cmake or lidef/lidef.h missing under ${PREFIX}")
endif()
# Implementation headers stay in the build tree; each library's headers sit under its own prefix.
foreach(h lane_math.h edge_jet.h newton_cg.h target_path.h mesh_queries.h)
  if(EXISTS ${PREFIX}/include/lidef/${h} OR EXISTS ${PREFIX}/include/lidef/internal/${h})
    message(FATAL_ERROR "install: implementation header ${h} was installed")
  endif()
endforeach()
foreach(h analysis/certificate_report.h analysis/deform_outputs.h opencl/opencl_backend.h cage/auto_cage.h)
  if(NOT EXISTS ${PREFIX}/include/lidef/${h})
    message(FATAL_ERROR "install: public header lidef/${h} missing")
  endif()
endforeach()

set(configure_args -G ${GENERATOR} -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=${PREFIX})
if(CCACHE)
  list(APPEND configure_args -DCMAKE_CXX_COMPILER_LAUNCHER=${CCACHE})
endif()

# The example, from its own folder.
run("configure deform_and_certify" COMMAND ${CMAKE_COMMAND} -S ${SOURCE_DIR}/examples/cpp/deform_and_certify
    -B ${WORK_DIR}/deform_and_certify ${configure_args})
run("build deform_and_certify" COMMAND ${CMAKE_COMMAND} --build ${WORK_DIR}/deform_and_certify)
# beam_bend with parameters that keep the run to seconds (a coarse subspace and sampling).
file(READ ${SOURCE_DIR}/data/scenarios/beam_bend.json scenario)
string(JSON scenario SET "${scenario}" parameters
       [=[{"reduced_dof": 60, "samples": 4000, "max_iterations": 30}]=])
file(WRITE ${WORK_DIR}/beam_bend_small.json "${scenario}")
run("deform_and_certify" COMMAND ${WORK_DIR}/deform_and_certify/deform_and_certify ${WORK_DIR}/beam_bend_small.json
    --models ${SOURCE_DIR}/data/models EXPECT "\ncertified: locally injective")

# The tutorial's C++ program: its ```cpp blocks in order, one source file. The text is made a CMake list of
# lines with its own ';', '[' and ']' hidden first (they would split or join list items).
file(READ ${SOURCE_DIR}/docs/tutorial.md text)
string(REPLACE ";" "@SEMI@" text "${text}")
string(REPLACE "[" "@LB@" text "${text}")
string(REPLACE "]" "@RB@" text "${text}")
string(REPLACE "\n" ";" lines "${text}")
set(program "")
set(inside OFF)
foreach(line IN LISTS lines)
  if(line STREQUAL "```cpp")
    set(inside ON)
  elseif(inside AND line STREQUAL "```")
    set(inside OFF)
  elseif(inside)
    string(APPEND program "${line}\n")
  endif()
endforeach()
string(REPLACE "@SEMI@" ";" program "${program}")
string(REPLACE "@LB@" "[" program "${program}")
string(REPLACE "@RB@" "]" program "${program}")
if(program STREQUAL "")
  message(FATAL_ERROR "docs/tutorial.md has no ```cpp block")
endif()
file(MAKE_DIRECTORY ${WORK_DIR}/tutorial-src)
file(WRITE ${WORK_DIR}/tutorial-src/tutorial.cpp "${program}")
file(WRITE ${WORK_DIR}/tutorial-src/CMakeLists.txt [=[
cmake_minimum_required(VERSION 3.20)
project(tutorial LANGUAGES C CXX)
set(CMAKE_CXX_STANDARD 17)
find_package(lidef CONFIG REQUIRED)
add_executable(tutorial tutorial.cpp)
target_link_libraries(tutorial PRIVATE lidef::core)
]=])
run("configure tutorial" COMMAND ${CMAKE_COMMAND} -S ${WORK_DIR}/tutorial-src -B ${WORK_DIR}/tutorial ${configure_args})
run("build tutorial" COMMAND ${CMAKE_COMMAND} --build ${WORK_DIR}/tutorial)
run("tutorial" COMMAND ${WORK_DIR}/tutorial/tutorial WORKING_DIRECTORY ${SOURCE_DIR} EXPECT "certified")
