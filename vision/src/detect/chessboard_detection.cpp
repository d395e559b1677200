// Chessboard and ChArUco detection mapped onto TargetBoard corner ids.
#include <algorithm>
#include <cmath>
#include <map>

#include <fmt/format.h>
#include <opencv2/aruco.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "robocal/vision/edge_fit.hpp"
#include "robocal/vision/target_detection.hpp"

namespace robocal::vision {
namespace {

std::optional<cv::aruco::PREDEFINED_DICTIONARY_NAME> aruco_dictionary(const std::string& n) {
  using D = cv::aruco::PREDEFINED_DICTIONARY_NAME;
  static const std::map<std::string, D> names = {{"DICT_4X4_50", D::DICT_4X4_50},
                                                 {"DICT_4X4_100", D::DICT_4X4_100},
                                                 {"DICT_4X4_250", D::DICT_4X4_250},
                                                 {"DICT_4X4_1000", D::DICT_4X4_1000},
                                                 {"DICT_5X5_50", D::DICT_5X5_50},
                                                 {"DICT_5X5_100", D::DICT_5X5_100},
                                                 {"DICT_5X5_250", D::DICT_5X5_250},
                                                 {"DICT_5X5_1000", D::DICT_5X5_1000},
                                                 {"DICT_6X6_50", D::DICT_6X6_50},
                                                 {"DICT_6X6_100", D::DICT_6X6_100},
                                                 {"DICT_6X6_250", D::DICT_6X6_250},
                                                 {"DICT_6X6_1000", D::DICT_6X6_1000},
                                                 {"DICT_7X7_50", D::DICT_7X7_50},
                                                 {"DICT_7X7_100", D::DICT_7X7_100},
                                                 {"DICT_7X7_250", D::DICT_7X7_250},
                                                 {"DICT_7X7_1000", D::DICT_7X7_1000},
                                                 {"DICT_ARUCO_ORIGINAL", D::DICT_ARUCO_ORIGINAL},
                                                 {"DICT_APRILTAG_16h5", D::DICT_APRILTAG_16h5},
                                                 {"DICT_APRILTAG_25h9", D::DICT_APRILTAG_25h9},
                                                 {"DICT_APRILTAG_36h10", D::DICT_APRILTAG_36h10},
                                                 {"DICT_APRILTAG_36h11", D::DICT_APRILTAG_36h11}};
  const auto it = names.find(n);
  if (it == names.end()) return std::nullopt;
  return it->second;
}

// Median of the fitted edge spread along square sides between neighbouring corners (the same
// sharpness measure as for AprilTags).
double chessboard_edge_blur(const cv::Mat& gray, const std::map<int, Eigen::Vector2d>& by_id,
                            int per_row) {
  std::vector<double> blurs;
  for (const auto& [id, p] : by_id) {
    for (int next : {id + 1, id + per_row}) {
      if (next == id + 1 && (id + 1) % per_row == 0) continue;
      const auto it = by_id.find(next);
      if (it == by_id.end()) continue;
      const double len = (it->second - p).norm();
      if (len < 12.0) continue;
      if (const auto fit =
              fit_edge_between(gray, p, it->second, std::min(4.0, 0.2 * len), 0.25 * len)) {
        blurs.push_back(fit->blur_sigma);
      }
    }
    if (blurs.size() >= 40) break;
  }
  if (blurs.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::nth_element(blurs.begin(), blurs.begin() + static_cast<long>(blurs.size() / 2), blurs.end());
  return blurs[blurs.size() / 2];
}

void sub_pixel(const cv::Mat& gray, std::vector<cv::Point2f>& pts, double square_px,
               const ChessboardDetectorOptions& options) {
  const int half =
      std::clamp(static_cast<int>(std::lround(options.subpix_window_fraction * square_px)), 2, 10);
  cv::cornerSubPix(gray, pts, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
}

void fill(TargetDetection& out, const TargetBoard& board,
          const std::map<int, Eigen::Vector2d>& by_id) {
  for (const auto& [id, px] : by_id) {
    const auto p = corner_point(board, id);
    if (!p) continue;
    out.corner_ids.push_back(id);
    out.board_points.push_back(*p);
    out.pixels.push_back(px);
  }
}

}  // namespace

TargetDetection detect_chessboard_board(const cv::Mat& gray, const TargetBoard& board,
                                        const ChessboardDetectorOptions& options) {
  TargetDetection out;
  if (board.spec.kind != TargetKind::kChessboard) {
    out.reason = "target is not a chessboard";
    return out;
  }
  if (gray.empty() || gray.type() != CV_8UC1) {
    out.reason = "not an 8-bit grey image";
    return out;
  }
  const int nx = board.spec.cols - 1;
  const int ny = board.spec.rows - 1;
  std::vector<cv::Point2f> pts;
  const bool ok = cv::findChessboardCorners(
      gray, cv::Size(nx, ny), pts, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
  if (!ok || static_cast<int>(pts.size()) != nx * ny) {
    out.reason = "chessboard not found (all inner corners must be visible)";
    return out;
  }
  auto at = [&](int i, int j) {
    const auto& p = pts[static_cast<size_t>(j * nx + i)];
    return Eigen::Vector2d(p.x, p.y);
  };
  {
    const Eigen::Vector2d dx = at(1, 0) - at(0, 0);
    const Eigen::Vector2d dy = at(0, 1) - at(0, 0);
    sub_pixel(gray, pts, std::sqrt(std::abs(dx.x() * dy.y() - dx.y() * dy.x())), options);
  }
  auto value = [&](const Eigen::Vector2d& p) {
    const int x = std::clamp(static_cast<int>(std::lround(p.x())), 0, gray.cols - 1);
    const int y = std::clamp(static_cast<int>(std::lround(p.y())), 0, gray.rows - 1);
    return static_cast<double>(gray.at<unsigned char>(y, x));
  };
  // OpenCV's scan order may start at any corner and run either way. Of the four flips of its
  // grid (plus transposes for square boards) the board's own labelling is the one that keeps
  // the handedness of a non-mirrored view (board x, y = image right, down when upright) and
  // puts the black top-left square at corner id 0.
  struct Labelling {
    bool flip_i, flip_j, transpose;
  };
  std::vector<Labelling> candidates;
  for (int t = 0; t < (nx == ny ? 2 : 1); ++t)
    for (int fi = 0; fi < 2; ++fi)
      for (int fj = 0; fj < 2; ++fj) candidates.push_back({fi == 1, fj == 1, t == 1});
  // Image point of board inner corner (bi, bj) under a labelling.
  auto image_of = [&](const Labelling& l, int bi, int bj) {
    int i = l.transpose ? bj : bi;
    int j = l.transpose ? bi : bj;
    if (l.flip_i) i = nx - 1 - i;
    if (l.flip_j) j = ny - 1 - j;
    return at(i, j);
  };
  const Labelling* chosen = nullptr;
  for (const auto& l : candidates) {
    const Eigen::Vector2d o = image_of(l, 0, 0);
    const Eigen::Vector2d ex = image_of(l, 1, 0) - o;
    const Eigen::Vector2d ey = image_of(l, 0, 1) - o;
    if (ex.x() * ey.y() - ex.y() * ey.x() <= 0.0) continue;
    // Corner id 0 touches the black top-left square (outside, diagonally) and the white square
    // to its upper right.
    if (value(o - 0.5 * ex - 0.5 * ey) < value(o + 0.5 * ex - 0.5 * ey)) {
      chosen = &l;
      break;
    }
  }
  if (chosen == nullptr) {
    out.reason = "board seen mirrored";
    return out;
  }
  std::map<int, Eigen::Vector2d> by_id;
  for (int bj = 0; bj < ny; ++bj)
    for (int bi = 0; bi < nx; ++bi) by_id[bj * nx + bi] = image_of(*chosen, bi, bj);
  fill(out, board, by_id);
  out.edge_blur_px = chessboard_edge_blur(gray, by_id, nx);
  out.status = DetectionStatus::kFound;
  return out;
}

TargetDetection detect_charuco_board(const cv::Mat& gray, const TargetBoard& board,
                                     const ChessboardDetectorOptions& options) {
  TargetDetection out;
  if (board.spec.kind != TargetKind::kCharuco) {
    out.reason = "target is not a ChArUco board";
    return out;
  }
  if (gray.empty() || gray.type() != CV_8UC1) {
    out.reason = "not an 8-bit grey image";
    return out;
  }
  const auto dict_name = aruco_dictionary(board.spec.dictionary);
  if (!dict_name) {
    out.reason = "unknown ArUco dictionary " + board.spec.dictionary;
    return out;
  }
  const auto dict = cv::aruco::getPredefinedDictionary(*dict_name);
  const auto cv_board = cv::aruco::CharucoBoard::create(
      board.spec.cols, board.spec.rows, static_cast<float>(board.spec.square_size),
      static_cast<float>(board.spec.marker_size), dict);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<std::vector<cv::Point2f>> rejected;
  std::vector<int> marker_ids;
  auto params = cv::aruco::DetectorParameters::create();
  cv::aruco::detectMarkers(gray, dict, marker_corners, marker_ids, params, rejected);
  // Markers of this board only.
  std::map<int, const TargetMarker*> markers;
  for (const auto& m : board.markers) markers[m.id] = &m;
  std::map<int, int> seen;
  for (int id : marker_ids) ++seen[id];
  std::vector<int> duplicated;
  for (const auto& [id, n] : seen)
    if (n > 1 && markers.count(id) != 0) duplicated.push_back(id);
  if (!duplicated.empty()) {
    out.reason = fmt::format("marker ids seen more than once: {}", fmt::join(duplicated, ", "));
    return out;
  }
  if (marker_ids.empty()) {
    out.reason = "no ArUco markers found";
    return out;
  }
  std::vector<cv::Point2f> corners;
  std::vector<int> ids;
  cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, gray, cv_board, corners, ids,
                                       cv::noArray(), cv::noArray(), 2);
  if (ids.empty()) {
    out.reason = "markers found but no chessboard corner could be interpolated";
    return out;
  }
  for (auto& c : corners) {
    c.x += static_cast<float>(kOpenCv46CharucoOffset);
    c.y += static_cast<float>(kOpenCv46CharucoOffset);
  }
  // Square size in px from the markers (their side is marker_size).
  double side_px = 0.0;
  // Shortest side per marker: foreshortening shrinks squares along one direction only.
  for (const auto& mc : marker_corners) {
    double shortest = cv::norm(mc[1] - mc[0]);
    for (size_t k = 1; k < 4; ++k) shortest = std::min(shortest, cv::norm(mc[(k + 1) % 4] - mc[k]));
    side_px += shortest / static_cast<double>(marker_corners.size());
  }
  const double square_px = side_px * board.spec.square_size / board.spec.marker_size;
  // The cornerSubPix window must stay inside the white margin between the square's edges and
  // its marker, or the marker's edges pull the corner.
  ChessboardDetectorOptions charuco_options = options;
  const double margin_fraction = 0.5 * (1.0 - board.spec.marker_size / board.spec.square_size);
  charuco_options.subpix_window_fraction =
      std::min(options.subpix_window_fraction, 0.7 * margin_fraction);
  sub_pixel(gray, corners, square_px, charuco_options);

  // Verify each corner against a homography fitted to the nearby markers' corners.
  std::vector<Eigen::Vector3d> mk_board;
  std::vector<Eigen::Vector2d> mk_px;
  for (size_t m = 0; m < marker_ids.size(); ++m) {
    const auto it = markers.find(marker_ids[m]);
    if (it == markers.end()) continue;
    for (size_t k = 0; k < 4; ++k) {
      mk_board.push_back(it->second->corners[k]);
      // detectMarkers' corners are in OpenCV's convention already (measured: |bias| < 0.05 px).
      mk_px.emplace_back(marker_corners[m][k].x, marker_corners[m][k].y);
    }
  }
  const double limit = std::max(options.max_marker_disagreement_px, 0.15 * square_px);
  std::map<int, Eigen::Vector2d> by_id;
  int dropped = 0;
  for (size_t i = 0; i < ids.size(); ++i) {
    const auto p = corner_point(board, ids[i]);
    if (!p) continue;
    std::vector<cv::Point2f> src;
    std::vector<cv::Point2f> dst;
    for (size_t k = 0; k < mk_board.size(); ++k) {
      if ((mk_board[k] - *p).norm() < 1.6 * board.spec.square_size) {
        src.emplace_back(static_cast<float>(mk_board[k].x()), static_cast<float>(mk_board[k].y()));
        dst.emplace_back(static_cast<float>(mk_px[k].x()), static_cast<float>(mk_px[k].y()));
      }
    }
    if (src.size() < 4) {
      ++dropped;
      continue;
    }
    const cv::Mat h = cv::findHomography(src, dst, 0);
    if (h.empty()) {
      ++dropped;
      continue;
    }
    std::vector<cv::Point2f> in = {
        cv::Point2f(static_cast<float>(p->x()), static_cast<float>(p->y()))};
    std::vector<cv::Point2f> pred;
    cv::perspectiveTransform(in, pred, h);
    const Eigen::Vector2d px(corners[i].x, corners[i].y);
    if ((px - Eigen::Vector2d(pred[0].x, pred[0].y)).norm() > limit) {
      ++dropped;
      continue;
    }
    by_id[ids[i]] = px;
  }
  if (by_id.empty()) {
    out.reason = "no interpolated corner agreed with its markers";
    return out;
  }
  fill(out, board, by_id);
  out.edge_blur_px = chessboard_edge_blur(gray, by_id, board.spec.cols - 1);
  const int total = (board.spec.cols - 1) * (board.spec.rows - 1);
  for (const auto& [id, m] : markers)
    if (seen.count(id) == 0) out.missing_marker_ids.push_back(id);
  if (static_cast<int>(by_id.size()) == total) {
    out.status = DetectionStatus::kFound;
  } else {
    out.status = DetectionStatus::kPartial;
    out.reason = fmt::format("{} of {} corners found", by_id.size(), total);
    if (dropped > 0)
      out.reason += fmt::format(" ({} dropped: disagree with their markers)", dropped);
    if (!out.missing_marker_ids.empty()) {
      out.reason += fmt::format("; markers missing: {}", fmt::join(out.missing_marker_ids, ", "));
    }
  }
  return out;
}

TargetDetection detect_target(const cv::Mat& gray, const TargetBoard& board,
                              AprilTagDetector& apriltag_detector) {
  switch (board.spec.kind) {
    case TargetKind::kAprilTagGrid:
      return detect_apriltag_board(gray, board, apriltag_detector);
    case TargetKind::kChessboard:
      return detect_chessboard_board(gray, board);
    case TargetKind::kCharuco:
      return detect_charuco_board(gray, board);
  }
  return {};
}

}  // namespace robocal::vision
