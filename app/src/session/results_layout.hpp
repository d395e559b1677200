#pragma once
// Where each results file of a session lives (app/SESSION.md, "results/"). Every path to a
// results file is spelled here and nowhere else; each file has one reader/writer pair in
// session/results_files.hpp.
#include <filesystem>
#include <string>

namespace robocal::app {

struct ResultsLayout {
  std::filesystem::path session;  // the session folder

  // Paths relative to the session folder, as reports name them.
  static constexpr const char* kRig = "results/rig.json";
  static constexpr const char* kMeasuredPoses = "results/measured_poses.json";
  static constexpr const char* kPixelObservations = "results/pixel_observations.json";
  static constexpr const char* kMeasurements = "results/measurements.yaml";
  static constexpr const char* kIdentification = "results/identification.json";
  static constexpr const char* kCalibratedRobot = "results/calibrated_robot.yaml";
  static constexpr const char* kCalibratedRobotPixels = "results/calibrated_robot_pixels.yaml";
  static constexpr const char* kCamerasFolder = "results/cameras/";
  static constexpr const char* kReportPage = "results/report.html";
  static constexpr const char* kHeldOut = "results/held_out.json";

  [[nodiscard]] std::filesystem::path dir() const { return session / "results"; }
  [[nodiscard]] std::filesystem::path camera(const std::string& name) const {
    return dir() / "cameras" / (name + ".yaml");
  }
  [[nodiscard]] std::filesystem::path rig() const { return session / kRig; }
  [[nodiscard]] std::filesystem::path measured_poses() const { return session / kMeasuredPoses; }
  [[nodiscard]] std::filesystem::path pixel_observations() const {
    return session / kPixelObservations;
  }
  [[nodiscard]] std::filesystem::path measurements() const { return session / kMeasurements; }
  [[nodiscard]] std::filesystem::path identification() const { return session / kIdentification; }
  [[nodiscard]] std::filesystem::path calibrated_robot() const {
    return session / kCalibratedRobot;
  }
  [[nodiscard]] std::filesystem::path calibrated_robot_pixels() const {
    return session / kCalibratedRobotPixels;
  }
  // The calibration report a person opens in a browser (`robocal report`).
  [[nodiscard]] std::filesystem::path report_page() const { return session / kReportPage; }
  // Held-out poses measured by the cameras (the wizard's validation step): the error of a fit
  // made without them. Not validation.json, which compares with a simulation's truth.
  [[nodiscard]] std::filesystem::path held_out() const { return session / kHeldOut; }
  // Stage reports: results/<stage>.json (measure, validation) and the demo's demo.json.
  [[nodiscard]] std::filesystem::path report(const std::string& stage) const {
    return dir() / (stage + ".json");
  }
  // The hidden truth of a simulated session (read by validate only).
  [[nodiscard]] std::filesystem::path truth_dir() const { return session / "truth"; }
  [[nodiscard]] std::filesystem::path truth() const { return truth_dir() / "truth.json"; }
};

}  // namespace robocal::app
