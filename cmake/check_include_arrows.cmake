# Fails when a part includes a header of a part it may not depend on (ARCHITECTURE.md, "Arrows").
# Run as a test: cmake -DROOT=<source dir> -P cmake/check_include_arrows.cmake
#
# Each part lists the parts whose public headers (robocal/<part>/...) it may include; a part may
# always include its own. calib may use vision's camera models only (robocal_vision_camera:
# camera_model.hpp, camera_models.hpp, camera_parameter_names.hpp): the rule for "vision" under
# calib is that narrow list. Nothing includes app's headers except app.
#
# Inside app, each folder of app/src lists the folders it may include (ARCHITECTURE.md,
# "app/src: the product's shape"); a folder with no rule fails the check, so a new folder gets
# its arrows when it is made.
#
# Inside vision the same holds for the rooms of vision/src (ARCHITECTURE.md, "vision/src"): a
# room includes its own headers and those of the rooms it lists. A room's internal header is
# included by room ("fit/corner_noise.hpp"); a public header robocal/vision/X.hpp belongs to the
# room that holds X.cpp, and the public headers with no source of their own (camera_models.hpp,
# observations.hpp, errors.hpp: the types every room speaks) to models/.
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

# app/src folder -> app/src folders it may include (besides itself). cli is the command line's
# common ground (exit codes, progress, JSON output); commands sit on top of everything.
set(app_allowed_cli "")
set(app_allowed_simcell "")
set(app_allowed_session "cli")
set(app_allowed_summary "session")
set(app_allowed_batch "cli")
set(app_allowed_stages "cli;session;simcell;summary")
set(app_allowed_live "cli;session;simcell;stages;summary")
set(app_allowed_wizard "cli;live;session;stages;summary")
set(app_allowed_commands "batch;cli;live;session;simcell;stages;summary;wizard")

# vision/src room -> vision/src rooms it may include (besides itself). detect/ sits above
# calibrate/: it hands its detections to the intrinsic calibration (to_calibration_view, the
# image-folder pipeline); calibrate/ reads measure/'s pose measurements (hand-eye).
set(vision_allowed_models "")
set(vision_allowed_fit "models")
set(vision_allowed_render "models")
set(vision_allowed_measure "fit;models")
set(vision_allowed_calibrate "fit;measure;models")
set(vision_allowed_detect "calibrate;models")

set(violations "")

# The rooms of vision/src, and the room of every source file by its name (for public headers).
file(GLOB vision_entries LIST_DIRECTORIES true RELATIVE "${ROOT}/vision/src" "${ROOT}/vision/src/*")
set(vision_rooms "")
foreach(entry IN LISTS vision_entries)
  if(IS_DIRECTORY "${ROOT}/vision/src/${entry}")
    list(APPEND vision_rooms "${entry}")
    if(NOT DEFINED vision_allowed_${entry})
      list(APPEND violations "vision/src/${entry}: a room with no arrows (add its rule here and in ARCHITECTURE.md)")
    endif()
    file(GLOB room_sources RELATIVE "${ROOT}/vision/src/${entry}" "${ROOT}/vision/src/${entry}/*.cpp")
    foreach(room_source IN LISTS room_sources)
      string(REGEX REPLACE "\\.cpp$" "" stem "${room_source}")
      set(vision_room_of_${stem} "${entry}")
    endforeach()
  endif()
endforeach()

# Every source of vision/src is in a room.
file(GLOB vision_loose "${ROOT}/vision/src/*.cpp" "${ROOT}/vision/src/*.hpp")
foreach(loose IN LISTS vision_loose)
  file(RELATIVE_PATH rel "${ROOT}" "${loose}")
  list(APPEND violations "${rel}: a source in no room of vision/src (ARCHITECTURE.md, \"vision/src\")")
endforeach()

# The room a vision file belongs to ("" outside vision/src's rooms and public headers).
function(vision_room_of_file source out)
  file(RELATIVE_PATH rel "${ROOT}/vision" "${source}")
  set(room "")
  if(rel MATCHES "^src/([a-z_]+)/")
    set(room "${CMAKE_MATCH_1}")
  elseif(rel MATCHES "^include/robocal/vision/([a-z_0-9]+)\\.hpp$")
    set(room "${vision_room_of_${CMAKE_MATCH_1}}")
    if(room STREQUAL "")
      set(room "models")
    endif()
  endif()
  set(${out} "${room}" PARENT_SCOPE)
endfunction()

# The room an include of a vision file reaches ("" for the same folder or outside vision).
function(vision_room_of_include header out)
  set(room "")
  if(header MATCHES "^robocal/vision/([a-z_0-9]+)\\.hpp$")
    set(room "${vision_room_of_${CMAKE_MATCH_1}}")
    if(room STREQUAL "")
      set(room "models")
    endif()
  elseif(header MATCHES "^([a-z_]+)/")
    if(CMAKE_MATCH_1 IN_LIST vision_rooms)
      set(room "${CMAKE_MATCH_1}")
    endif()
  endif()
  set(${out} "${room}" PARENT_SCOPE)
endfunction()

file(GLOB_RECURSE vision_files "${ROOT}/vision/*.hpp" "${ROOT}/vision/*.cpp")
foreach(source IN LISTS vision_files)
  vision_room_of_file("${source}" from_room)
  if(from_room STREQUAL "")
    continue()
  endif()
  file(STRINGS "${source}" lines REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"]")
  foreach(line IN LISTS lines)
    string(REGEX MATCH "[<\"]([^>\"]+)[>\"]" _ "${line}")
    vision_room_of_include("${CMAKE_MATCH_1}" to_room)
    if(NOT to_room STREQUAL "" AND NOT to_room STREQUAL from_room
       AND NOT to_room IN_LIST vision_allowed_${from_room})
      file(RELATIVE_PATH rel "${ROOT}" "${source}")
      list(APPEND violations "${rel}: ${from_room}/ includes <${CMAKE_MATCH_1}> (${to_room}/)")
    endif()
  endforeach()
endforeach()

file(GLOB app_entries LIST_DIRECTORIES true RELATIVE "${ROOT}/app/src" "${ROOT}/app/src/*")
set(app_folders "")
foreach(entry IN LISTS app_entries)
  if(IS_DIRECTORY "${ROOT}/app/src/${entry}")
    list(APPEND app_folders "${entry}")
    if(NOT DEFINED app_allowed_${entry})
      list(APPEND violations "app/src/${entry}: a folder with no arrows (add its rule here and in ARCHITECTURE.md)")
    endif()
  endif()
endforeach()

set(parts core vision calib robotio planner app)
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
        elseif(header MATCHES "^robocal_version\\.hpp$")
          set(target_part "app")
        elseif(header MATCHES "^([a-z_]+)/")
          # ${CMAKE_MATCH_1} in the same if() would be the previous match: test it apart.
          if(CMAKE_MATCH_1 IN_LIST app_folders)
            set(target_part "app")
          endif()
        endif()
        if(part STREQUAL "app" AND target_part STREQUAL "app" AND header MATCHES "^([a-z_]+)/")
          set(to_folder "${CMAKE_MATCH_1}")
          file(RELATIVE_PATH rel "${ROOT}/app/src" "${source}")
          set(from_folder "")
          if(rel MATCHES "^([a-z_]+)/")
            set(from_folder "${CMAKE_MATCH_1}")
          endif()
          if(NOT from_folder STREQUAL "" AND NOT from_folder STREQUAL to_folder
             AND NOT to_folder IN_LIST app_allowed_${from_folder})
            list(APPEND violations "app/src/${rel}: ${from_folder}/ includes <${header}> (${to_folder}/)")
          endif()
          continue()
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
message(STATUS "include arrows: every part, app folder and vision room includes only what it may use")
