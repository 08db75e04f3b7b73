# ctest build.layer_guard.<layer> (tests/CMakeLists.txt): cmake -P with
#   BUILD_DIR, SOURCE_DIR  the build tree the probes are built in and the repository
#   LAYER                  the layer's name, for messages
#   OWNED                  its folders (comma-separated), scanned for includes that climb out
#   SEES, SEEN_HEADERS     the probe including one header of each layer it may see
#   REFUSED                probe=header pairs (comma-separated), one per layer above
# Passes when the SEES probe compiles, every REFUSED probe stops at its header not being found,
# and no source of the layer includes a path with "..", which the include path cannot guard.
string(REPLACE "," ";" owned "${OWNED}")
string(REPLACE "," ";" seen_headers "${SEEN_HEADERS}")
string(REPLACE "," ";" refused "${REFUSED}")

# A probe of a header that no longer exists would fail for the wrong reason.
foreach(header ${seen_headers})
  if(NOT EXISTS ${SOURCE_DIR}/${header})
    message(FATAL_ERROR "layer ${LAYER}: probe header ${header} does not exist; update tests/CMakeLists.txt")
  endif()
endforeach()

function(build_probe target rc_var out_var)
  execute_process(COMMAND ${CMAKE_COMMAND} --build ${BUILD_DIR} --target ${target}
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  set(${rc_var} ${rc} PARENT_SCOPE)
  set(${out_var} "${out}" PARENT_SCOPE)
endfunction()

build_probe(${SEES} rc out)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "layer ${LAYER}: ${SEES} (${seen_headers}) must compile but did not:\n${out}")
endif()
message(STATUS "layer ${LAYER} sees ${seen_headers}")

foreach(pair ${refused})
  string(REGEX MATCH "^([^=]+)=(.+)$" _ "${pair}")
  set(target ${CMAKE_MATCH_1})
  set(header ${CMAKE_MATCH_2})
  if(NOT EXISTS ${SOURCE_DIR}/${header})
    message(FATAL_ERROR "layer ${LAYER}: probe header ${header} does not exist; update tests/CMakeLists.txt")
  endif()
  build_probe(${target} rc out)
  if(rc EQUAL 0)
    message(FATAL_ERROR "layer ${LAYER}: ${header}, a header of a higher layer, compiles here (${target})")
  endif()
  string(REPLACE "." "\\." header_regex "${header}")
  # GCC: "<header>: No such file or directory"; clang: "'<header>' file not found".
  if(NOT out MATCHES "${header_regex}'?:? (No such file or directory|file not found)")
    message(FATAL_ERROR "layer ${LAYER}: ${target} failed, but not because ${header} was not found:\n${out}")
  endif()
  message(STATUS "layer ${LAYER} refuses ${header}")
endforeach()

foreach(dir ${owned})
  file(GLOB_RECURSE sources ${SOURCE_DIR}/${dir}/*.h ${SOURCE_DIR}/${dir}/*.cc)
  foreach(source ${sources})
    file(STRINGS ${source} climbing REGEX "^[ \t]*#[ \t]*include[ \t]*[\"<][^\">]*\\.\\.")
    if(climbing)
      message(FATAL_ERROR "layer ${LAYER}: ${source} includes a path with \"..\" (${climbing}); include from a layer root instead, e.g. \"sim/config.h\"")
    endif()
  endforeach()
endforeach()
