#pragma once
// Detections recorded beside the images they came from. `robocal collect` detects the end-effector
// board in every frame for its settled-frame test while the robot moves on; it writes those
// detections into the pose folder (detections.json, app/SESSION.md), and measure takes them
// instead of detecting the same images again.
//
// An entry is used only for the very image it was made from (the file's size and 64-bit FNV-1a
// hash) and only by the same detector (detection_signature: every detector option and the
// board's definition). An image replaced afterwards, another board file or other detector
// options are detected afresh; a record that is missing, unreadable or of another format is
// ignored the same way. Numbers round-trip exactly (JSON with shortest round-trip doubles; NaN as
// null), so a recorded detection equals the detection made again.
#include "robocal/vision/apriltag_detector.hpp"
#include "robocal/vision/target.hpp"
#include "robocal/vision/target_detection.hpp"

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace robocal::vision {

struct RecordedDetection {
  std::uintmax_t size = 0;  // bytes of the image file
  std::uint64_t hash = 0;   // FNV-1a 64 of the image file's bytes
  int width = 0;            // of the image
  int height = 0;
  TargetDetection detection;
};

// The file name (no folder) of each recorded image, and its detection.
using DetectionRecord = std::map<std::string, RecordedDetection>;

// What makes two detections of one image equal: the detector's options and the board.
std::string detection_signature(const TargetBoard& board, const AprilTagDetectorOptions& options);

// FNV-1a 64 of a byte string (an encoded image as written).
std::uint64_t content_hash(std::string_view bytes);

// The record's file text (JSON).
std::string detection_record_to_json(const std::string& signature, const DetectionRecord& record);

// The entries of `file` made with `signature`; empty when the file is absent, unreadable, of
// another format or made with another signature (the images are then simply detected).
DetectionRecord read_detection_record(const std::filesystem::path& file,
                                      const std::string& signature);

// The entry's detection when `image` is the file it was made from (same size and hash).
const RecordedDetection* matching_entry(const DetectionRecord& record,
                                        const std::filesystem::path& image, std::string_view bytes);

// File name of a pose folder's record (app/SESSION.md).
inline constexpr const char* kDetectionRecordFile = "detections.json";

}  // namespace robocal::vision
