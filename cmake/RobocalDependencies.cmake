# Every dependency is a Debian 12 package (scripts/bootstrap.sh installs them), found the ordinary
# way: find_package where the package ships a CMake config, pkg-config otherwise.
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
function(robocal_use_shared_ceres)
  get_target_property(archive Ceres::ceres IMPORTED_LOCATION_RELEASE)
  string(REGEX REPLACE "\\.a$" ".so" shared "${archive}")
  if(NOT archive MATCHES "\\.a$" OR NOT EXISTS "${shared}")
    message(FATAL_ERROR "robocal links the shared Ceres library; expected ${shared} next to "
                        "${archive} (Debian package libceres-dev)")
  endif()
  set_target_properties(Ceres::ceres PROPERTIES IMPORTED_LOCATION_RELEASE "${shared}"
                                                IMPORTED_LOCATION "${shared}")
endfunction()

find_package(Ceres 2.1 REQUIRED)
# Debian's Ceres config imports the static libceres.a. Its objects carry their own, unsanitized
# copies of Eigen's inline allocator (plain malloc), and in a sanitizer build the linker may pick
# those copies for our code too, whose matching free is Eigen's sanitizer-build one: a
# heap-buffer-overflow that is not ours. The shared libceres.so exports only Ceres' API (Eigen
# stays hidden inside it), so every Eigen allocation of our code stays in our code.
robocal_use_shared_ceres()
find_package(OpenCV 4.6 REQUIRED COMPONENTS core imgproc imgcodecs calib3d aruco)
find_package(apriltag 3.3 REQUIRED)
find_package(yaml-cpp 0.7 REQUIRED)
find_package(nlohmann_json 3.11 REQUIRED)
find_package(CLI11 2.1 REQUIRED)
find_package(fmt 9 REQUIRED)
find_package(spdlog 1.10 REQUIRED)
# libpng directly for the capture's fast lossless writing (robotio/src/camera/png_encode.hpp).
find_package(PNG 1.6 REQUIRED)
# FCL ships a CMake config (target `fcl`, which links ccd and octomap).
find_package(fcl 0.7 REQUIRED)
find_package(PkgConfig REQUIRED)
pkg_check_modules(ARAVIS REQUIRED IMPORTED_TARGET aravis-0.8)
pkg_check_modules(LIBV4L2 REQUIRED IMPORTED_TARGET libv4l2)
# URDF export/import (calib/serial_exports): Debian's liburdfdom-dev.
pkg_check_modules(URDFDOM REQUIRED IMPORTED_TARGET urdfdom)
# Test-only packages (scripts/bootstrap.sh --tests). Without them the program still configures
# and builds (scripts/demo.sh installs only what it needs): the tests or benchmarks are left out
# for this configure run and found again by the next one once installed. ctest then finds no
# tests and fails (noTestsAction in CMakePresets.json), so a test run never passes empty.
if(ROBOCAL_BUILD_TESTS)
  find_package(GTest 1.12 QUIET)
  if(GTest_FOUND)
    include(GoogleTest)
  else()
    message(STATUS "Tests left out: GoogleTest/GoogleMock not found "
                   "(Debian libgtest-dev libgmock-dev: bash scripts/bootstrap.sh --tests)")
    set(ROBOCAL_BUILD_TESTS OFF)
  endif()
endif()
if(ROBOCAL_BUILD_BENCH)
  find_package(benchmark 1.7 QUIET)
  if(NOT benchmark_FOUND)
    message(STATUS "Benchmarks left out: Google Benchmark not found "
                   "(Debian libbenchmark-dev: bash scripts/bootstrap.sh --tests)")
    set(ROBOCAL_BUILD_BENCH OFF)
  endif()
endif()
find_package(Threads REQUIRED)
