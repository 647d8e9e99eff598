# Small helpers so every component states its targets the same way (STYLE.md habit 8).

set(AVE_WARNING_FLAGS -Wall -Wextra -Wno-unused-parameter -Wno-missing-field-initializers)
if(AVE_WARNINGS_AS_ERRORS)
  list(APPEND AVE_WARNING_FLAGS -Werror)
endif()

# ave_library(NAME SRCS ... PUBLIC_DEPS ... PRIVATE_DEPS ...)
function(ave_library name)
  cmake_parse_arguments(ARG "" "" "SRCS;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(${name} STATIC ${ARG_SRCS})
  target_include_directories(${name} PUBLIC ${PROJECT_SOURCE_DIR})
  target_compile_options(${name} PRIVATE ${AVE_WARNING_FLAGS})
  target_link_libraries(${name} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
endfunction()

# ave_executable(NAME SRCS ... DEPS ...): lands in <build>/bin.
function(ave_executable name)
  cmake_parse_arguments(ARG "" "" "SRCS;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SRCS})
  target_compile_options(${name} PRIVATE ${AVE_WARNING_FLAGS})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS})
endfunction()

# ave_test(NAME SRCS ... DEPS ... [LABELS ...] [TIMEOUT s]): a gtest binary registered with ctest.
function(ave_test name)
  if(NOT AVE_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "TIMEOUT" "SRCS;DEPS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SRCS})
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/tests)
  target_compile_options(${name} PRIVATE ${AVE_WARNING_FLAGS})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gmock GTest::gtest_main)
  add_test(NAME ${name} COMMAND ${name})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  set_tests_properties(${name} PROPERTIES TIMEOUT ${ARG_TIMEOUT})
  if(ARG_LABELS)
    set_tests_properties(${name} PROPERTIES LABELS "${ARG_LABELS}")
  endif()
endfunction()

# ave_fuzzer(NAME SRCS ... DEPS ...): a libFuzzer target (only with -DAVE_FUZZ=ON and clang) in
# <build>/fuzz. The SRCS are the code under test, compiled into the target with AddressSanitizer
# (+ LeakSanitizer) and UndefinedBehaviorSanitizer; the DEPS (Debian's and our own libraries) are not.
# Used by fusion_server/fuzz/ and sensor_agent/fuzz/ (each stays within its component's layering).
set(AVE_FUZZ_FLAGS -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined -g -O1)
# ave_fuzz_objects(NAME SRCS ... DEPS ...): code under test compiled once with the fuzz flags, for
# several targets to link (in their DEPS) instead of each compiling it again; DEPS give it include
# paths and are linked into whoever links it.
function(ave_fuzz_objects name)
  cmake_parse_arguments(ARG "" "" "SRCS;DEPS" ${ARGN})
  add_library(${name} OBJECT ${ARG_SRCS})
  target_include_directories(${name} PRIVATE ${PROJECT_SOURCE_DIR})
  target_compile_options(${name} PRIVATE ${AVE_FUZZ_FLAGS})
  target_link_libraries(${name} PUBLIC ${ARG_DEPS})
endfunction()
function(ave_fuzzer name)
  cmake_parse_arguments(ARG "" "" "SRCS;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SRCS})
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/fuzz)
  target_include_directories(${name} PRIVATE ${PROJECT_SOURCE_DIR})
  target_compile_options(${name} PRIVATE ${AVE_FUZZ_FLAGS})
  target_link_options(${name} PRIVATE ${AVE_FUZZ_FLAGS})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS})
endfunction()

# ave_write_link_graph(FILE): one line per target this project defines, tab-separated:
#   <target> <its folder, relative to the project> <direct link items> <sources>
# (lists ;-separated). tests/layering_test.py reads it to check that no model_store/ or
# fusion_server/ target reaches a sensor_agent/ (or viewer_client/, tests/) one, directly or
# through others. Call once, at the end of the top-level CMakeLists, when every target exists.
function(ave_write_link_graph file)
  set(dirs ${PROJECT_SOURCE_DIR})
  set(text "")
  while(dirs)
    list(POP_FRONT dirs dir)
    get_property(subdirs DIRECTORY ${dir} PROPERTY SUBDIRECTORIES)
    list(APPEND dirs ${subdirs})
    get_property(targets DIRECTORY ${dir} PROPERTY BUILDSYSTEM_TARGETS)
    file(RELATIVE_PATH rel_dir ${PROJECT_SOURCE_DIR} ${dir})
    foreach(target IN LISTS targets)
      get_target_property(type ${target} TYPE)
      if(type STREQUAL "INTERFACE_LIBRARY")
        get_target_property(links ${target} INTERFACE_LINK_LIBRARIES)
        set(sources "")
      else()
        get_target_property(links ${target} LINK_LIBRARIES)
        get_target_property(sources ${target} SOURCES)
      endif()
      if(NOT links)
        set(links "")
      endif()
      if(NOT sources)
        set(sources "")
      endif()
      string(APPEND text "${target}\t${rel_dir}\t${links}\t${sources}\n")
    endforeach()
  endwhile()
  file(WRITE ${file} "${text}")
endfunction()
