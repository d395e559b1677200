# Compiler settings every robocal target shares: warnings (as errors unless ROBOCAL_WERROR=OFF)
# and the sanitizer switch used by the `asan` preset.
option(ROBOCAL_SANITIZE "Build with AddressSanitizer + UndefinedBehaviorSanitizer" OFF)

add_library(robocal_defaults INTERFACE)
target_compile_options(robocal_defaults INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor -Wcast-align -Wunused
  -Woverloaded-virtual -Wnull-dereference -Wformat=2 -Wimplicit-fallthrough
  $<$<BOOL:${ROBOCAL_WERROR}>:-Werror>)
if(ROBOCAL_SANITIZE)
  target_compile_options(robocal_defaults INTERFACE
    -fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer)
  target_link_options(robocal_defaults INTERFACE -fsanitize=address,undefined)
endif()

# ccache makes the second and later CI builds cheap on our two cores.
find_program(ROBOCAL_CCACHE ccache)
if(ROBOCAL_CCACHE AND NOT CMAKE_CXX_COMPILER_LAUNCHER)
  set(CMAKE_C_COMPILER_LAUNCHER ${ROBOCAL_CCACHE})
  set(CMAKE_CXX_COMPILER_LAUNCHER ${ROBOCAL_CCACHE})
endif()

# robocal_library(NAME part SOURCES ... DEPS ...): a part's library with public headers under
# <part>/include/robocal/<part>/.
function(robocal_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(${name} ${ARG_SOURCES})
  target_include_directories(${name} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
  target_link_libraries(${name} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE robocal_defaults ${ARG_PRIVATE_DEPS})
endfunction()
