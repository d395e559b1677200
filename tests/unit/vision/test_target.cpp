// Targets: geometry, ids, files, and that the drawn patterns are what AprilTag 3.3 and OpenCV
// 4.6 detect (decoded ids, corner order, corner positions), on a frontal raster of is_black().
#include "robocal/vision/target.hpp"
#include "robocal/vision/target_io.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <gtest/gtest.h>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <map>

#include "target_boards.hpp"

namespace rv = robocal::vision;
namespace rt = robocal::testing;

namespace {

// Frontal image of the paper, `px` metres per pixel, 4x4 supersampled; black 0, white 255.
// Board point P appears at pixel ((P - extent_min) / px - 0.5) in OpenCV's convention.
cv::Mat frontal_raster(const rv::TargetBoard& board, double px) {
  const Eigen::Vector2d size = board.extent_max - board.extent_min;
  cv::Mat img(static_cast<int>(size.y() / px), static_cast<int>(size.x() / px), CV_8U);
  for (int v = 0; v < img.rows; ++v)
    for (int u = 0; u < img.cols; ++u) {
      int white = 0;
      for (int sy = 0; sy < 4; ++sy)
        for (int sx = 0; sx < 4; ++sx)
          white += !rv::is_black(board, board.extent_min.x() + (u + (sx + 0.5) / 4) * px,
                                 board.extent_min.y() + (v + (sy + 0.5) / 4) * px);
      img.at<uchar>(v, u) = static_cast<uchar>(white * 255 / 16);
    }
  return img;
}

Eigen::Vector2d raster_pixel(const rv::TargetBoard& board, const Eigen::Vector3d& p, double px) {
  return (p.head<2>() - board.extent_min) / px - Eigen::Vector2d(0.5, 0.5);
}

rv::TargetSpec april_spec() {
  auto s = rt::grid_spec(rv::TargetKind::kAprilTagGrid, 4, 3);
  s.tag_size = 0.04;
  s.tag_spacing = 0.01;
  s.first_id = 5;
  return s;
}

}  // namespace

TEST(Target, AprilTagGridGeometry) {
  const auto board = rv::build_target(april_spec());
  ASSERT_EQ(board.corners.size(), 48u);
  ASSERT_EQ(board.markers.size(), 12u);
  EXPECT_EQ(board.spec.margin, 0.01);
  // Tag 5 + (row 1 * 4 + col 2) = 11: top-left at (2, 1) * 0.05.
  const Eigen::Vector3d tl = *rv::corner_point(board, 11 * 4 + 3);
  EXPECT_NEAR(tl.x(), 0.10, 1e-15);
  EXPECT_NEAR(tl.y(), 0.05, 1e-15);
  EXPECT_NEAR((*rv::corner_point(board, 11 * 4 + 0) - tl - Eigen::Vector3d(0, 0.04, 0)).norm(), 0,
              1e-15);
  EXPECT_FALSE(rv::corner_point(board, 4 * 4).has_value());  // tag 4 is not on the board
  // The black border: just inside the tag's corner is black, just outside white (quiet zone).
  EXPECT_TRUE(rv::is_black(board, tl.x() + 1e-4, tl.y() + 1e-4));
  EXPECT_FALSE(rv::is_black(board, tl.x() - 1e-4, tl.y() + 1e-4));
  EXPECT_FALSE(rv::is_black(board, tl.x() - 0.0049, tl.y() + 0.01));  // spacing is white
  EXPECT_NEAR(board.extent_max.x(), 4 * 0.04 + 3 * 0.01 + 0.01, 1e-15);
}

TEST(Target, AprilTagGridColumnMajorAndExplicitIds) {
  auto s = april_spec();
  s.column_major = true;
  auto board = rv::build_target(s);
  // Row 0, col 1 holds id 5 + 1 * rows = 8.
  EXPECT_NEAR(rv::corner_point(board, 8 * 4 + 3)->x(), 0.05, 1e-15);
  s.ids = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 3};
  std::string field;
  EXPECT_EQ(rv::check_target_spec(s, &field), "tag id 3 appears twice");
  EXPECT_EQ(field, "ids");
  s.ids.back() = 400;
  board = rv::build_target(s);
  EXPECT_NEAR(rv::corner_point(board, 400 * 4 + 3)->x(), 0.15, 1e-15);
  EXPECT_NEAR(rv::corner_point(board, 400 * 4 + 3)->y(), 0.10, 1e-15);
}

TEST(Target, AprilTag33DecodesBoardWithDocumentedCornerOrder) {
  const auto board = rv::build_target(april_spec());
  const double px = 0.04 / 8 / 6;  // 6 pixels per module
  const cv::Mat img = frontal_raster(board, px);
  apriltag_family_t* family = tag36h11_create();
  apriltag_detector_t* det = apriltag_detector_create();
  apriltag_detector_add_family(det, family);
  det->quad_decimate = 1.0;
  det->nthreads = 1;
  image_u8_t im{img.cols, img.rows, static_cast<int32_t>(img.step), img.data};
  zarray_t* found = apriltag_detector_detect(det, &im);
  std::map<int, int> seen;
  double worst = 0;
  for (int i = 0; i < zarray_size(found); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(found, i, &d);
    ++seen[d->id];
    for (int k = 0; k < 4; ++k) {
      const auto p = rv::corner_point(board, d->id * 4 + k);
      ASSERT_TRUE(p.has_value()) << d->id;
      // AprilTag's (0,0) is the top-left pixel's corner: -0.5 px to OpenCV's convention.
      const Eigen::Vector2d detected(d->p[k][0] - 0.5, d->p[k][1] - 0.5);
      worst = std::max(worst, (detected - raster_pixel(board, *p, px)).norm());
    }
  }
  apriltag_detections_destroy(found);
  apriltag_detector_destroy(det);
  tag36h11_destroy(family);
  EXPECT_EQ(seen.size(), 12u);
  for (const auto& [id, count] : seen) {
    EXPECT_EQ(count, 1);
    EXPECT_TRUE(id >= 5 && id < 17);
  }
  EXPECT_LT(worst, 0.3);  // order and convention right: a wrong corner would be >= 48 px off
}

TEST(Target, ChessboardFoundByOpenCV) {
  const auto board = rt::chessboard_board(7, 5, 0.02);
  ASSERT_EQ(board.corners.size(), 24u);
  const double px = 0.02 / 24;
  const cv::Mat img = frontal_raster(board, px);
  std::vector<cv::Point2f> pts;
  ASSERT_TRUE(cv::findChessboardCorners(img, cv::Size(6, 4), pts));
  cv::cornerSubPix(img, pts, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-4));
  // OpenCV may start at either end; compare as sets.
  double worst = 0;
  for (const auto& c : board.corners) {
    const Eigen::Vector2d e = raster_pixel(board, c.point, px);
    double best = 1e9;
    for (const auto& p : pts) best = std::min(best, std::hypot(p.x - e.x(), p.y - e.y()));
    worst = std::max(worst, best);
  }
  EXPECT_LT(worst, 0.1);
}

TEST(Target, CharucoMatchesOpenCV46DetectionWithHalfPixelOffset) {
  // Even row count: the layout that changed in 4.6.
  const auto board = rt::charuco_board(5, 4, 0.04, 0.03);
  ASSERT_EQ(board.corners.size(), 12u);
  ASSERT_EQ(board.markers.size(), 10u);
  const double px = 0.03 / 8 / 6;
  const cv::Mat img = frontal_raster(board, px);
  const auto dict = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_6X6_250);
  const auto cvb = cv::aruco::CharucoBoard::create(5, 4, 0.04f, 0.03f, dict);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(img, dict, marker_corners, marker_ids);
  ASSERT_EQ(marker_ids.size(), 10u);
  for (size_t m = 0; m < marker_ids.size(); ++m) {
    const auto& mk = board.markers[static_cast<size_t>(marker_ids[m])];
    ASSERT_EQ(mk.id, marker_ids[m]);
    const Eigen::Vector2d e = raster_pixel(board, mk.corners[0], px);
    EXPECT_LT(std::hypot(marker_corners[m][0].x - e.x(), marker_corners[m][0].y - e.y()), 1.5);
  }
  std::vector<cv::Point2f> corners;
  std::vector<int> ids;
  cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, img, cvb, corners, ids);
  ASSERT_EQ(ids.size(), 12u);
  Eigen::Vector2d mean_offset(0, 0);
  for (size_t k = 0; k < ids.size(); ++k) {
    const Eigen::Vector2d e = raster_pixel(board, *rv::corner_point(board, ids[k]), px);
    mean_offset += Eigen::Vector2d(corners[k].x - e.x(), corners[k].y - e.y());
  }
  mean_offset /= static_cast<double>(ids.size());
  // The known OpenCV 4.6 offset: interpolateCornersCharuco reports +0.5 px in x and y.
  EXPECT_NEAR(mean_offset.x(), 0.5, 0.05);
  EXPECT_NEAR(mean_offset.y(), 0.5, 0.05);
}

namespace {
std::string target_error(const std::string& text) {
  try {
    rv::parse_target_yaml(text, "board.yaml");
  } catch (const rv::FileFormatError& e) {
    return e.what();
  }
  return "no error";
}
}  // namespace

TEST(TargetFile, ParsesAndRoundTrips) {
  const auto board = rv::parse_target_yaml(
      "type: apriltag_grid\ncols: 6\nrows: 4\ntag_size: 0.03\ntag_spacing: 0.009\nfirst_id: 10\n",
      "board.yaml");
  EXPECT_EQ(board.corners.size(), 96u);
  EXPECT_TRUE(rv::corner_point(board, 10 * 4).has_value());
  const auto again = rv::parse_target_yaml(rv::target_to_yaml(board.spec), "again.yaml");
  ASSERT_EQ(again.corners.size(), board.corners.size());
  for (size_t i = 0; i < board.corners.size(); ++i) {
    EXPECT_EQ(again.corners[i].id, board.corners[i].id);
    EXPECT_EQ(again.corners[i].point, board.corners[i].point);
  }
}

TEST(TargetFile, ErrorsNameFileAndLine) {
  EXPECT_EQ(target_error("type: apriltag_grid\ncols: 6\nrows: 4\ntag_size: -0.03\n"),
            "board.yaml:4: tag_size must be a positive length in metres");
  EXPECT_EQ(
      target_error("type: apriltag_grid\ncols: 6\nrows: 4\ntag_size: 0.08\ntag_spacing: 0.01\n"),
      "board.yaml:5: tag_spacing must be at least 2 tag modules (0.020000 m) so every tag "
      "keeps its own white quiet zone");
  EXPECT_EQ(target_error("type: apriltag_grid\ncols: 2\nrows: 1\ntag_size: 0.08\nids: [3, 3]\n"),
            "board.yaml:5: tag id 3 appears twice");
  EXPECT_EQ(target_error("type: apriltag_grid\ncols: 2\nrows: 1\ntag_size: 0.08\nfirst_id: 586\n"),
            "board.yaml:5: tag id 587 is outside tag36h11 (0..586)");
  EXPECT_EQ(
      target_error("type: apriltag_grid\ncols: 2\nrows: 1\ntag_size: 0.08\nfamily: tag99\n"),
      "board.yaml:5: unknown AprilTag family 'tag99' (expected tag36h11, tag25h9 or tag16h5)");
  EXPECT_EQ(target_error("type: charuco\ncols: 5\nrows: 4\nsquare_size: 0.04\nmarker_size: 0.05\n"),
            "board.yaml:5: marker_size must be positive and smaller than square_size");
  EXPECT_EQ(target_error("type: chessboard\ncols: 1\nrows: 4\nsquare_size: 0.04\n"),
            "board.yaml:2: cols must be at least 2 (got 1)");
  EXPECT_EQ(target_error("type: chessboard\ncols: 5\nrows: 4\nsquare: 0.04\n"),
            "board.yaml:4: unknown key 'square' (allowed: type, name, cols, rows, margin, "
            "square_size)");
  EXPECT_EQ(target_error("type: circles\n"),
            "board.yaml:1: unknown target type 'circles' (expected apriltag_grid, chessboard or "
            "charuco)");
  EXPECT_EQ(target_error("type: chessboard\ncols: 5\nrows: 4\n"),
            "board.yaml:1: missing required key 'square_size'");
}

TEST(TargetFile, SvgIsTrueScale) {
  auto s = rt::grid_spec(rv::TargetKind::kChessboard, 3, 2);
  s.square_size = 0.025;
  s.margin = 0.01;
  const std::string svg = rv::target_to_svg(rv::build_target(s));
  EXPECT_NE(svg.find("width=\"95mm\" height=\"70mm\" viewBox=\"0 0 95 70\""), std::string::npos);
  // 3 black squares (0,0), (2,0), (1,1) -> 3 runs.
  size_t rects = 0;
  for (size_t pos = 0; (pos = svg.find("<rect x", pos)) != std::string::npos; ++pos) ++rects;
  EXPECT_EQ(rects, 1u + 3u);
  EXPECT_NE(svg.find("<rect x=\"10\" y=\"10\" width=\"25\" height=\"25\"/>"), std::string::npos);
}
