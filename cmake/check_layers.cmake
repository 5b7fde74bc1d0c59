# Fails when a file includes from a layer above its own.
#   cmake -DROOT=<source tree> -P cmake/check_layers.cmake
# Layers, bottom to top (docs/ARCHITECTURE.md). A file in include/desplat/<L>/ or src/<L>/ may
#   - include "desplat/<M>/…" only when M is L or below it;
#   - include a private header "<M>/…" of src/ only when M is L itself, and only from src/:
#     a public header includes public headers alone, since an installed tree has no src/.
# Every public header lives in a layer folder: include/desplat/<L>/.
cmake_minimum_required(VERSION 3.22)
set(LAYERS core raster io sfm comm train eval synth jobs)

if(NOT ROOT)
  message(FATAL_ERROR "check_layers: pass -DROOT=<source tree>")
endif()

get_filename_component(ROOT "${ROOT}" ABSOLUTE)
set(problems "")
file(GLOB stray LIST_DIRECTORIES true RELATIVE "${ROOT}/include/desplat" "${ROOT}/include/desplat/*")
foreach(entry IN LISTS stray)
  if(NOT entry IN_LIST LAYERS)
    string(APPEND problems "include/desplat/${entry}: not a layer folder (layers: ${LAYERS})\n")
  endif()
endforeach()

foreach(layer IN LISTS LAYERS)
  list(FIND LAYERS ${layer} rank)
  file(GLOB_RECURSE files RELATIVE "${ROOT}"
       "${ROOT}/include/desplat/${layer}/*.hpp" "${ROOT}/src/${layer}/*.hpp" "${ROOT}/src/${layer}/*.cpp")
  foreach(file IN LISTS files)
    file(STRINGS "${ROOT}/${file}" includes REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
    foreach(line IN LISTS includes)
      string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*\"([^\"]*)\".*" "\\1" target "${line}")
      if(target MATCHES "^desplat/([^/]+)/")
        set(used ${CMAKE_MATCH_1})
        list(FIND LAYERS ${used} used_rank)
        if(used_rank EQUAL -1)
          string(APPEND problems "${file}: includes \"${target}\": '${used}' is not a layer\n")
        elseif(used_rank GREATER rank)
          string(APPEND problems "${file}: includes \"${target}\" from layer '${used}', above '${layer}'\n")
        endif()
      elseif(target MATCHES "^desplat/")
        string(APPEND problems "${file}: includes \"${target}\", which is in no layer folder\n")
      elseif(file MATCHES "^include/")
        string(APPEND problems "${file}: includes \"${target}\", which is not a public header; an installed public header can include only \"desplat/…\" headers\n")
      elseif(target MATCHES "^([^/]+)/")
        set(used ${CMAKE_MATCH_1})
        if(used IN_LIST LAYERS AND NOT used STREQUAL layer)
          string(APPEND problems "${file}: includes \"${target}\", a private header of layer '${used}'; use its public header in include/desplat/${used}/\n")
        endif()
      endif()
    endforeach()
  endforeach()
endforeach()

if(problems)
  message(NOTICE "${problems}")  # NOTICE: printed as is, one problem per line
  message(FATAL_ERROR "layer dependency check failed (see the lines above)")
endif()
message(STATUS "layer dependencies: every include points to the same layer or one below it")
