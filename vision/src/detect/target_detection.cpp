#include "robocal/vision/target_detection.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <set>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace robocal::vision {
namespace {

std::string lower_extension(const std::filesystem::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

// libpng/libjpeg decode truncated files with only a warning; check the end markers ourselves.
std::string truncation_problem(const std::filesystem::path& path, const std::string& ext) {
  errno = 0;
  std::ifstream f(path, std::ios::binary);
  // An unreadable file (permissions, I/O error) is not a short one: say why it cannot be read.
  if (!f) return std::string("cannot open for reading (") + std::strerror(errno) + ")";
  f.seekg(0, std::ios::end);
  const auto size = static_cast<long long>(f.tellg());
  if (size < 0) return std::string("cannot read (") + std::strerror(errno) + ")";
  if (size < 16) return fmt::format("file too short to be an image ({} bytes)", size);
  char head[4] = {0, 0, 0, 0};
  f.seekg(0);
  f.read(head, 4);
  if (ext == ".png" && std::string(head + 1, 3) != "PNG") return "not a PNG file (bad signature)";
  if ((ext == ".jpg" || ext == ".jpeg") && !(static_cast<unsigned char>(head[0]) == 0xFF &&
                                             static_cast<unsigned char>(head[1]) == 0xD8)) {
    return "not a JPEG file (bad signature)";
  }
  if (ext == ".png") {
    char tail[12];
    f.seekg(size - 12);
    f.read(tail, 12);
    if (std::string(tail + 4, 4) != "IEND") return "truncated PNG (no IEND chunk at the end)";
  } else if (ext == ".jpg" || ext == ".jpeg") {
    // The EOI marker FF D9 ends a complete JPEG (some writers append a few padding bytes).
    const long long n = std::min<long long>(size, 64);
    std::string tail(static_cast<size_t>(n), '\0');
    f.seekg(size - n);
    f.read(tail.data(), n);
    if (tail.find("\xFF\xD9") == std::string::npos)
      return "truncated JPEG (no end-of-image marker)";
  }
  return {};
}

}  // namespace

LoadedImage load_gray_image(const std::filesystem::path& path) {
  LoadedImage out;
  const std::string name = path.string();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    out.error = name + ": not a readable file";
    return out;
  }
  const std::string ext = lower_extension(path);
  if (const std::string t = truncation_problem(path, ext); !t.empty()) {
    out.error = name + ": " + t;
    return out;
  }
  cv::Mat img;
  try {
    img = cv::imread(name, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    out.error = name + ": cannot decode image (" + e.what() + ")";
    return out;
  }
  if (img.empty()) {
    out.error = name + ": cannot decode image (unknown format or corrupt data)";
    return out;
  }
  return gray_image(img, name);
}

LoadedImage gray_image(const cv::Mat& img, const std::string& name) {
  LoadedImage out;
  if (img.depth() != CV_8U) {
    const int bits = img.depth() == CV_16U || img.depth() == CV_16S ? 16 : 32;
    out.error = fmt::format(
        "{}: {}-bit image; 8-bit grey or colour expected (convert it, keeping "
        "the full range)",
        name, bits);
    return out;
  }
  if (img.channels() == 3) {
    cv::cvtColor(img, out.gray, cv::COLOR_BGR2GRAY);
  } else if (img.channels() == 4) {
    cv::cvtColor(img, out.gray, cv::COLOR_BGRA2GRAY);
  } else if (img.channels() == 1) {
    out.gray = img;
  } else {
    out.error = fmt::format("{}: {} channels; grey or colour expected", name, img.channels());
  }
  return out;
}

namespace {

// Whether the board and the detector can work together; the reason when not.
std::string apriltag_board_mismatch(const TargetBoard& board, const AprilTagDetector& detector) {
  if (board.spec.kind != TargetKind::kAprilTagGrid) return "target is not an AprilTag grid";
  if (board.spec.family != detector.options().family) {
    return "detector family " + detector.options().family + " differs from the board's " +
           board.spec.family;
  }
  return {};
}

// The board's corners among `tags` (tags of other boards ignored), with the status: found,
// partial (which markers are missing) or rejected (none of the board, or an id seen twice).
TargetDetection board_detection_from_tags(const std::vector<TagDetection>& tags,
                                          const TargetBoard& board) {
  TargetDetection out;
  std::map<int, const TargetMarker*> markers;
  for (const auto& m : board.markers) markers[m.id] = &m;
  std::map<int, int> seen;
  for (const auto& t : tags) ++seen[t.id];
  std::vector<int> duplicated;
  for (const auto& [id, n] : seen) {
    if (n > 1 && markers.count(id) != 0) duplicated.push_back(id);
  }
  if (!duplicated.empty()) {
    out.reason = fmt::format("tag ids seen more than once: {}", fmt::join(duplicated, ", "));
    return out;
  }
  std::vector<double> blurs;
  for (const auto& t : tags) {
    const auto it = markers.find(t.id);
    if (it == markers.end()) continue;  // not on this board
    for (size_t k = 0; k < 4; ++k) {
      out.corner_ids.push_back(t.id * 4 + static_cast<int>(k));
      out.board_points.push_back(it->second->corners[k]);
      out.pixels.push_back(t.corners[k]);
    }
    if (t.refined) {
      blurs.push_back(t.edge_blur_px);
      if (t.corner_covariance.allFinite() && t.corner_covariance.trace() > 0.0) {
        CornerGroup g;
        for (int k = 0; k < 4; ++k) g.corner_ids.push_back(t.id * 4 + k);
        g.covariance = t.corner_covariance;
        out.corner_groups.push_back(std::move(g));
      }
    }
  }
  if (!blurs.empty()) {
    std::nth_element(blurs.begin(), blurs.begin() + static_cast<long>(blurs.size() / 2),
                     blurs.end());
    out.edge_blur_px = blurs[blurs.size() / 2];
  } else {
    out.edge_blur_px = std::numeric_limits<double>::quiet_NaN();
  }
  if (out.pixels.empty()) {
    out.reason = tags.empty() ? "no tags found" : "no tag of this board found";
    return out;
  }
  for (const auto& [id, m] : markers) {
    if (seen.count(id) == 0) out.missing_marker_ids.push_back(id);
  }
  if (out.missing_marker_ids.empty()) {
    out.status = DetectionStatus::kFound;
  } else {
    out.status = DetectionStatus::kPartial;
    out.reason = fmt::format("{} of {} tags missing: {}", out.missing_marker_ids.size(),
                             markers.size(), fmt::join(out.missing_marker_ids, ", "));
  }
  return out;
}

}  // namespace

TargetDetection detect_apriltag_board(const cv::Mat& gray, const TargetBoard& board,
                                      AprilTagDetector& detector) {
  if (std::string why = apriltag_board_mismatch(board, detector); !why.empty()) {
    TargetDetection out;
    out.reason = std::move(why);
    return out;
  }
  return board_detection_from_tags(detector.detect(gray), board);
}

TargetDetection redetect_apriltag_board(const cv::Mat& gray, const TargetBoard& board,
                                        const TargetDetection& previous,
                                        AprilTagDetector& detector) {
  if (std::string why = apriltag_board_mismatch(board, detector); !why.empty()) {
    TargetDetection out;
    out.reason = std::move(why);
    return out;
  }
  // The tags whose four corners the earlier detection holds (corner id = 4 x tag id + k).
  std::map<int, TagDetection> tags;
  std::map<int, int> corners_of;
  for (std::size_t i = 0; i < previous.corner_ids.size(); ++i) {
    const int id = previous.corner_ids[i] / 4;
    TagDetection& tag = tags[id];
    tag.id = id;
    tag.corners[static_cast<std::size_t>(previous.corner_ids[i] % 4)] = previous.pixels[i];
    ++corners_of[id];
  }
  // A tag the earlier detection could not refine (too small or too blurred for the edge fit) was
  // kept with the library's corners; it cannot be refined here either, so a view holding one is
  // detected in full: a refinement would lose it and report the target as moved.
  std::set<int> refined;
  for (const CornerGroup& group : previous.corner_groups) {
    for (const int corner : group.corner_ids) refined.insert(corner / 4);
  }
  std::vector<TagDetection> complete;
  for (const auto& [id, tag] : tags) {
    if (corners_of[id] != 4) continue;
    if (refined.count(id) == 0) return detect_apriltag_board(gray, board, detector);
    complete.push_back(tag);
  }
  TargetDetection out = board_detection_from_tags(detector.refine_at(gray, complete), board);
  if (out.status == DetectionStatus::kRejected && !complete.empty()) {
    out.reason =
        "no tag found again where the earlier image had it (the target moved more "
        "than the refinement reaches, or is covered)";
  }
  return out;
}

CalibrationView to_calibration_view(const TargetDetection& detection, std::string name) {
  CalibrationView v;
  v.name = std::move(name);
  if (detection.status == DetectionStatus::kRejected) return v;
  v.corner_ids = detection.corner_ids;
  v.board_points = detection.board_points;
  v.pixels = detection.pixels;
  v.corner_groups = detection.corner_groups;
  return v;
}

std::string detection_status_name(DetectionStatus status) {
  switch (status) {
    case DetectionStatus::kFound:
      return "found";
    case DetectionStatus::kPartial:
      return "partial";
    case DetectionStatus::kRejected:
      return "rejected";
  }
  return "rejected";
}

}  // namespace robocal::vision
