# Fails when a part includes a header of a part it may not depend on (ARCHITECTURE.md, "Arrows").
# Run as a test: cmake -DROOT=<source dir> -P cmake/check_include_arrows.cmake
#
# Each part lists the parts whose public headers (robocal/<part>/...) it may include; a part may
# always include its own. calib may use vision's camera models only (robocal_vision_camera:
# camera_model.hpp, camera_models.hpp, camera_parameter_names.hpp): the rule for "vision" under
# calib is that narrow list. Nothing includes app's headers except app.
cmake_minimum_required(VERSION 3.25)
if(NOT ROOT)
  message(FATAL_ERROR "pass -DROOT=<source dir>")
endif()

# part -> folders holding its sources and headers
set(folders_core core)
set(folders_vision vision)
set(folders_calib calib)
set(folders_robotio robotio)
set(folders_planner planner)
set(folders_app app)

# part -> parts it may include (besides itself)
set(allowed_core "")
set(allowed_vision "core")
set(allowed_calib "core;vision_camera")
set(allowed_robotio "core;vision;calib")
set(allowed_planner "core;vision;calib")
set(allowed_app "core;vision;calib;robotio;planner")

# Headers of vision that calib may include (the camera models, no OpenCV).
set(vision_camera_headers
    "robocal/vision/camera_model.hpp;robocal/vision/camera_models.hpp;robocal/vision/camera_parameter_names.hpp")

set(parts core vision calib robotio planner app)
set(violations "")
foreach(part IN LISTS parts)
  foreach(folder IN LISTS folders_${part})
    if(NOT IS_DIRECTORY "${ROOT}/${folder}")
      continue()
    endif()
    file(GLOB_RECURSE sources "${ROOT}/${folder}/*.hpp" "${ROOT}/${folder}/*.h"
         "${ROOT}/${folder}/*.cpp" "${ROOT}/${folder}/*.cc")
    foreach(source IN LISTS sources)
      file(STRINGS "${source}" lines REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"]")
      foreach(line IN LISTS lines)
        string(REGEX MATCH "[<\"]([^>\"]+)[>\"]" _ "${line}")
        set(header "${CMAKE_MATCH_1}")
        # Which part does the header belong to?
        set(target_part "")
        if(header MATCHES "^robocal/([a-z_]+)/")
          set(target_part "${CMAKE_MATCH_1}")
        elseif(header MATCHES "^(cli|commands|session|stages|simcell|summary|live|batch)/"
               OR header MATCHES "^robocal_version\\.hpp$")
          set(target_part "app")
        endif()
        if(target_part STREQUAL "" OR target_part STREQUAL part)
          continue()
        endif()
        set(ok FALSE)
        if(target_part IN_LIST allowed_${part})
          set(ok TRUE)
        elseif(target_part STREQUAL "vision" AND "vision_camera" IN_LIST allowed_${part}
               AND header IN_LIST vision_camera_headers)
          set(ok TRUE)
        endif()
        if(NOT ok)
          file(RELATIVE_PATH rel "${ROOT}" "${source}")
          list(APPEND violations "${rel}: ${part} includes <${header}> (${target_part})")
        endif()
      endforeach()
    endforeach()
  endforeach()
endforeach()

if(violations)
  list(JOIN violations "\n  " text)
  message(FATAL_ERROR "includes against the arrows of ARCHITECTURE.md:\n  ${text}")
endif()
message(STATUS "include arrows: every part includes only the parts it may use")
