# robocal_robotio_camera: camera sources (Aravis GigE Vision / USB3 Vision, V4L2, simulated,
# recorded session folders) and synchronised capture. Included from robotio/CMakeLists.txt.
robocal_library(robocal_robotio_camera
  SOURCES
    src/camera/camera_source.cpp
    src/camera/camera_aravis.cpp
    src/camera/camera_fake_gige.cpp
    src/camera/camera_v4l2.cpp
    src/camera/camera_simulated.cpp
    src/camera/camera_recorded.cpp
    src/camera/capture.cpp
    src/camera/png_encode.cpp
    src/camera/camera_checks.cpp
    src/camera/capture_link.cpp
    src/camera/sim_truth.cpp
    src/camera/camera_open.cpp
  PUBLIC_DEPS robocal_vision robocal_robotio ${OpenCV_LIBS}
  PRIVATE_DEPS PkgConfig::ARAVIS PkgConfig::LIBV4L2 PNG::PNG fmt::fmt yaml-cpp
    nlohmann_json::nlohmann_json)
