// Board detection on rendered images of TargetBoards, and per-file image loading errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <limits>

#include <opencv2/imgcodecs.hpp>

#include "board_views.hpp"
#include "robocal/vision/detection_record.hpp"
#include "robocal/vision/image_detection.hpp"
#include "robocal/vision/target_detection.hpp"

namespace rv = robocal::vision;
namespace rt = robocal::testing;

namespace {

rv::TargetBoard tag_board() {
  return rt::apriltag_grid_board(4, 3, 0.04, 10);
}

using Rendered = rt::BoardView;

Rendered render_board(const rv::TargetBoard& board, double tilt, double blur, double noise) {
  const rt::SyntheticCamera cam{640, 512, 600.0, 319.5, 255.5};
  return rt::render_board_view(board, cam, 0.5, tilt, 20.0, 5.0, 319.5, 255.5, blur, noise);
}

// The board 0.5 m away, tilted 35 deg, its centre `du` px right of the principal point, with the
// image noise of `seed`: frames of a still (du = 0) or slightly moved target.
Rendered shifted_view(const rv::TargetBoard& board, double du, unsigned seed) {
  const rt::SyntheticCamera cam{640, 512, 600.0, 319.5, 255.5};
  return rt::render_board_view(board, cam, 0.5, 35.0, 20.0, 5.0, 319.5 + du, 255.5, 0.8, 2.0, seed);
}

std::filesystem::path temp_dir() {
  auto d = std::filesystem::temp_directory_path() /
           ("robocal_detect_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
  std::filesystem::create_directories(d);
  return d;
}

}  // namespace

// The detector's corner order must match the board's corner ids: every detected corner must lie
// where the board point projects.
TEST(AprilTagBoardDetection, CornerIdsMatchBoardGeometry) {
  const auto board = tag_board();
  const auto r = render_board(board, 35.0, 0.8, 2.0);
  rv::AprilTagDetector detector;
  const auto det = rv::detect_apriltag_board(r.image, board, detector);
  ASSERT_EQ(det.status, rv::DetectionStatus::kFound) << det.reason;
  EXPECT_EQ(det.pixels.size(), 4u * 12u);
  double sq = 0.0;
  for (size_t i = 0; i < det.pixels.size(); ++i) {
    const auto p = rv::corner_point(board, det.corner_ids[i]);
    ASSERT_TRUE(p.has_value());
    EXPECT_EQ((*p - det.board_points[i]).norm(), 0.0);
    const Eigen::Vector2d truth = rt::apply_h(r.h, p->head<2>());
    sq += (det.pixels[i] - truth).squaredNorm();
    EXPECT_LT((det.pixels[i] - truth).norm(), 0.1) << "corner " << det.corner_ids[i];
  }
  EXPECT_LT(std::sqrt(sq / static_cast<double>(det.pixels.size())), 0.03);
  EXPECT_GT(det.edge_blur_px, 0.7);
  EXPECT_LT(det.edge_blur_px, 1.0);
}

TEST(AprilTagBoardDetection, PartialDuplicateAndMirroredImages) {
  const auto board = tag_board();
  const auto r = render_board(board, 0.0, 0.8, 1.0);
  rv::AprilTagDetector detector;
  // Cover the first tag (id 10) with white paper.
  const auto& m = board.markers.front();
  ASSERT_EQ(m.id, 10);
  cv::Mat covered = r.image.clone();
  std::vector<cv::Point> poly;
  for (const auto& c : m.corners) {
    const Eigen::Vector2d px = rt::apply_h(r.h, c.head<2>());
    poly.emplace_back(static_cast<int>(px.x()), static_cast<int>(px.y()));
  }
  cv::Rect box = cv::boundingRect(poly);
  box -= cv::Point(3, 3);
  box += cv::Size(6, 6);
  covered(box).setTo(220);
  auto det = rv::detect_apriltag_board(covered, board, detector);
  EXPECT_EQ(det.status, rv::DetectionStatus::kPartial);
  EXPECT_EQ(det.missing_marker_ids, std::vector<int>{10});
  EXPECT_NE(det.reason.find("10"), std::string::npos);
  EXPECT_EQ(det.pixels.size(), 4u * 11u);

  // The same tag pasted a second time into the image: ambiguous, rejected.
  cv::Mat twice = r.image.clone();
  cv::Mat patch = r.image(box).clone();
  twice(box).setTo(220);  // keep only the pasted copies
  patch.copyTo(twice(cv::Rect(5, 5, box.width, box.height)));
  patch.copyTo(twice(cv::Rect(5, twice.rows - box.height - 5, box.width, box.height)));
  det = rv::detect_apriltag_board(twice, board, detector);
  EXPECT_EQ(det.status, rv::DetectionStatus::kRejected);
  EXPECT_NE(det.reason.find("more than once: 10"), std::string::npos) << det.reason;

  // Mirrored image: AprilTag codes do not decode mirrored, nothing usable comes out.
  cv::Mat mirrored;
  cv::flip(r.image, mirrored, 1);
  det = rv::detect_apriltag_board(mirrored, board, detector);
  EXPECT_EQ(det.status, rv::DetectionStatus::kRejected);
  EXPECT_FALSE(det.reason.empty());

  det = rv::detect_apriltag_board(cv::Mat(100, 100, CV_8UC1, cv::Scalar(200)), board, detector);
  EXPECT_EQ(det.status, rv::DetectionStatus::kRejected);
  EXPECT_EQ(det.reason, "no tags found");
}

// The second look of the settled-frame test: the tags of a first detection refined where they
// were in a later image. Within the refinement's reach (2 px) every corner is found again where
// the later view's homography puts it, as accurately as a full detection; beyond it, none is
// (a target that moved is not reported still), and the reason says so.
TEST(AprilTagBoardDetection, FoundAgainWhereItWasOnlyWithinReach) {
  const auto board = tag_board();
  const auto view = [&](double du, unsigned seed) { return shifted_view(board, du, seed); };
  rv::AprilTagDetector detector;
  const Rendered first_view = view(0.0, 1);
  const auto first = rv::detect_apriltag_board(first_view.image, board, detector);
  ASSERT_EQ(first.status, rv::DetectionStatus::kFound) << first.reason;

  for (const double du : {0.0, 0.4, 1.5}) {
    SCOPED_TRACE("moved " + std::to_string(du) + " px");
    const Rendered later_view = view(du, 2);  // new image noise, as in a second frame
    const auto again = rv::redetect_apriltag_board(later_view.image, board, first, detector);
    ASSERT_EQ(again.status, rv::DetectionStatus::kFound) << again.reason;
    EXPECT_EQ(again.corner_ids, first.corner_ids);
    EXPECT_EQ(again.corner_groups.size(), first.corner_groups.size());
    double sq = 0.0;
    for (std::size_t i = 0; i < again.pixels.size(); ++i) {
      const Eigen::Vector2d truth = rt::apply_h(later_view.h, again.board_points[i].head<2>());
      sq += (again.pixels[i] - truth).squaredNorm();
      EXPECT_LT((again.pixels[i] - truth).norm(), 0.1) << "corner " << again.corner_ids[i];
    }
    EXPECT_LT(std::sqrt(sq / static_cast<double>(again.pixels.size())), 0.03);
  }

  const Rendered far_view = view(8.0, 3);
  const auto lost = rv::redetect_apriltag_board(far_view.image, board, first, detector);
  EXPECT_EQ(lost.status, rv::DetectionStatus::kRejected);
  EXPECT_TRUE(lost.pixels.empty());
  EXPECT_NE(lost.reason.find("no tag found again"), std::string::npos) << lost.reason;

  // A tag the first detection lacks is not looked for: the later image has all twelve, the
  // first (covered) only eleven.
  rv::TargetDetection eleven = first;
  eleven.corner_ids.erase(eleven.corner_ids.begin(), eleven.corner_ids.begin() + 4);
  eleven.board_points.erase(eleven.board_points.begin(), eleven.board_points.begin() + 4);
  eleven.pixels.erase(eleven.pixels.begin(), eleven.pixels.begin() + 4);
  const auto partial = rv::redetect_apriltag_board(view(0.0, 4).image, board, eleven, detector);
  EXPECT_EQ(partial.status, rv::DetectionStatus::kPartial);
  EXPECT_EQ(partial.missing_marker_ids, std::vector<int>{first.corner_ids.front() / 4});

  rv::AprilTagDetectorOptions tag25h9;
  tag25h9.family = "tag25h9";
  rv::AprilTagDetector other_family(tag25h9);
  const auto mismatch = rv::redetect_apriltag_board(first_view.image, board, first, other_family);
  EXPECT_EQ(mismatch.status, rv::DetectionStatus::kRejected);
  EXPECT_NE(mismatch.reason.find("tag25h9"), std::string::npos) << mismatch.reason;
}

// Series of frames of one still view: the first image where the board is found is detected in
// full (as detect_in_images does), the later ones refined from it; an unreadable image in a
// series is reported and the next readable one becomes the reference.
TEST(AprilTagBoardDetection, ImageSeriesDetectFirstAndRefineTheRest) {
  const auto board = tag_board();
  const auto view = [&](double du, unsigned seed) { return shifted_view(board, du, seed); };
  const auto dir = temp_dir();
  std::vector<Rendered> views;
  const auto file = [&](const std::string& name, double du, unsigned seed) {
    views.push_back(view(du, seed));
    auto path = dir / name;
    cv::imwrite(path.string(), views.back().image);
    return path;
  };
  // Any size accepted (0 x 0): the checks of image size are detect_in_images' own.
  const auto request = [](const std::filesystem::path& path) {
    return rv::DetectionRequest{path, 0, 0, ""};
  };
  const std::vector<std::vector<rv::DetectionRequest>> series = {
      {request(file("a0.png", 0.0, 1)), request(file("a1.png", 0.3, 2)),
       request(dir / "missing.png")},
      {request(dir / "absent.png"), request(file("b1.png", 0.0, 3)),
       request(file("b2.png", -0.3, 4))}};
  const auto out = rv::detect_in_image_series(series, board, 2);
  ASSERT_EQ(out.size(), 2u);
  ASSERT_EQ(out[0].size(), 3u);
  ASSERT_EQ(out[1].size(), 3u);
  EXPECT_NE(out[0][2].problem.find("missing.png"), std::string::npos) << out[0][2].problem;
  EXPECT_NE(out[1][0].problem.find("absent.png"), std::string::npos) << out[1][0].problem;

  // The first found image of each series is detected exactly as detect_in_images detects it.
  const auto full =
      rv::detect_in_images({request(dir / "a0.png"), request(dir / "b1.png")}, board, 1);
  EXPECT_EQ(out[0][0].detection.pixels, full[0].detection.pixels);
  EXPECT_EQ(out[1][1].detection.pixels, full[1].detection.pixels);

  // Every found image: all 48 corners where its own view's homography puts them.
  const std::vector<std::pair<const rv::ImageDetection*, const Rendered*>> found = {
      {&out[0][0], &views[0]},
      {&out[0][1], &views[1]},
      {&out[1][1], &views[2]},
      {&out[1][2], &views[3]}};
  for (const auto& [d, v] : found) {
    ASSERT_TRUE(d->problem.empty()) << d->problem;
    ASSERT_EQ(d->detection.pixels.size(), 48u);
    for (std::size_t i = 0; i < d->detection.pixels.size(); ++i) {
      const Eigen::Vector2d truth = rt::apply_h(v->h, d->detection.board_points[i].head<2>());
      EXPECT_LT((d->detection.pixels[i] - truth).norm(), 0.1) << "corner " << i;
    }
  }
  std::filesystem::remove_all(dir);
}

// A detection recorded with its image (detection_record.hpp) round-trips exactly, is taken for that
// very file by the same detector, and is ignored for a changed file, another detector or board
// and a damaged record: those images are detected again.
TEST(DetectionRecord, TakenForTheSameImageAndDetectorOnly) {
  const auto board = tag_board();
  const auto dir = temp_dir();
  const Rendered view = shifted_view(board, 0.0, 1);
  std::vector<unsigned char> png;
  ASSERT_TRUE(cv::imencode(".png", view.image, png));
  std::ofstream(dir / "cam0_0.png", std::ios::binary)
      .write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  const rv::DetectionRequest plain{dir / "cam0_0.png", 0, 0, ""};
  const rv::TargetDetection detected = rv::detect_in_images({plain}, board, 1)[0].detection;
  ASSERT_EQ(detected.status, rv::DetectionStatus::kFound);
  ASSERT_FALSE(detected.corner_groups.empty());

  // What a recorder would write, but with every pixel moved by 1/8 px: when the record is taken,
  // the moved pixels come back, which detecting the image cannot give.
  rv::TargetDetection marked = detected;
  for (auto& p : marked.pixels) p += Eigen::Vector2d(0.125, -0.125);
  marked.edge_blur_px = std::numeric_limits<double>::quiet_NaN();
  const std::string signature = rv::detection_signature(board, rv::detector_options_for(board));
  const rv::DetectionRecord record = {
      {"cam0_0.png",
       {png.size(), rv::content_hash(std::string(png.begin(), png.end())), view.image.cols,
        view.image.rows, marked}}};
  std::ofstream(dir / rv::kDetectionRecordFile) << rv::detection_record_to_json(signature, record);

  const rv::DetectionRecord read =
      rv::read_detection_record(dir / rv::kDetectionRecordFile, signature);
  ASSERT_EQ(read.size(), 1u);
  const rv::TargetDetection& back = read.at("cam0_0.png").detection;
  EXPECT_EQ(back.status, marked.status);
  EXPECT_EQ(back.corner_ids, marked.corner_ids);
  EXPECT_EQ(back.pixels, marked.pixels);  // bit for bit
  EXPECT_EQ(back.board_points, marked.board_points);
  EXPECT_TRUE(std::isnan(back.edge_blur_px));
  ASSERT_EQ(back.corner_groups.size(), marked.corner_groups.size());
  for (std::size_t g = 0; g < back.corner_groups.size(); ++g) {
    EXPECT_EQ(back.corner_groups[g].corner_ids, marked.corner_groups[g].corner_ids);
    EXPECT_EQ(back.corner_groups[g].covariance, marked.corner_groups[g].covariance);
  }

  rv::DetectionRequest with_record = plain;
  with_record.record = &read;
  const auto taken = rv::detect_in_image_series({{with_record}}, board, 1)[0][0];
  EXPECT_TRUE(taken.problem.empty()) << taken.problem;
  EXPECT_EQ(taken.detection.pixels, marked.pixels);
  EXPECT_EQ(taken.width, view.image.cols);

  // Another detector (a different decimation) or board: nothing read.
  rv::AprilTagDetectorOptions finer = rv::detector_options_for(board);
  finer.quad_decimate = 1.0f;
  EXPECT_TRUE(rv::read_detection_record(dir / rv::kDetectionRecordFile,
                                        rv::detection_signature(board, finer))
                  .empty());
  const auto other_board = rt::apriltag_grid_board(4, 3, 0.05);
  EXPECT_NE(rv::detection_signature(other_board, rv::detector_options_for(other_board)), signature);

  // The image changed after recording (one pixel): detected again.
  cv::Mat changed = view.image.clone();
  changed.at<std::uint8_t>(0, 0) ^= 1;
  ASSERT_TRUE(cv::imwrite((dir / "cam0_0.png").string(), changed));
  const auto again = rv::detect_in_image_series({{with_record}}, board, 1)[0][0];
  ASSERT_TRUE(again.problem.empty()) << again.problem;
  EXPECT_NE(again.detection.pixels, marked.pixels);
  EXPECT_EQ(again.detection.corner_ids, detected.corner_ids);

  // A damaged record reads as none.
  std::ofstream(dir / rv::kDetectionRecordFile) << "{\"format\": \"robocal detection record 1\", ";
  EXPECT_TRUE(rv::read_detection_record(dir / rv::kDetectionRecordFile, signature).empty());
  EXPECT_TRUE(rv::read_detection_record(dir / "absent.json", signature).empty());
  std::filesystem::remove_all(dir);
}

TEST(ImageLoading, ClearErrorsPerFile) {
  const auto dir = temp_dir();
  const cv::Mat img(60, 80, CV_8UC1, cv::Scalar(100));
  ASSERT_TRUE(cv::imwrite((dir / "good.png").string(), img));
  ASSERT_TRUE(cv::imwrite((dir / "good.jpg").string(), img));
  cv::Mat colour(60, 80, CV_8UC3, cv::Scalar(10, 20, 30));
  ASSERT_TRUE(cv::imwrite((dir / "colour.png").string(), colour));
  ASSERT_TRUE(
      cv::imwrite((dir / "deep.png").string(), cv::Mat(60, 80, CV_16UC1, cv::Scalar(4000))));
  auto truncate = [&](const std::string& from, const std::string& to) {
    const auto size = std::filesystem::file_size(dir / from);
    std::string bytes(size / 2, '\0');
    std::ifstream(dir / from, std::ios::binary).read(bytes.data(), static_cast<long>(bytes.size()));
    std::ofstream(dir / to, std::ios::binary) << bytes;
  };
  truncate("good.png", "cut.png");
  truncate("good.jpg", "cut.jpg");
  std::ofstream(dir / "text.png") << "this is not an image at all, just some text";

  auto load = [&](const std::string& n) { return rv::load_gray_image(dir / n); };
  EXPECT_TRUE(load("good.png").error.empty());
  EXPECT_EQ(load("good.png").gray.type(), CV_8UC1);
  EXPECT_TRUE(load("good.jpg").error.empty());
  const auto c = load("colour.png");
  EXPECT_TRUE(c.error.empty());
  EXPECT_EQ(c.gray.type(), CV_8UC1);
  EXPECT_NE(load("deep.png").error.find("16-bit"), std::string::npos) << load("deep.png").error;
  EXPECT_NE(load("cut.png").error.find("truncated PNG"), std::string::npos)
      << load("cut.png").error;
  EXPECT_NE(load("cut.jpg").error.find("truncated JPEG"), std::string::npos)
      << load("cut.jpg").error;
  EXPECT_NE(load("text.png").error.find("text.png: not a PNG file"), std::string::npos);
  EXPECT_TRUE(load("text.png").gray.empty());
  EXPECT_NE(load("missing.png").error.find("not a readable file"), std::string::npos);
  EXPECT_NE(rv::load_gray_image(dir).error.find("not a readable file"), std::string::npos);
  std::filesystem::remove_all(dir);
}

namespace {

rv::TargetBoard charuco_board() {
  return rt::charuco_board(7, 5, 0.036195, 0.018256);
}

rv::TargetBoard chessboard(int cols, int rows) {
  return rt::chessboard_board(cols, rows, 0.03);
}

// Rendered at 1280x1024 so squares are ~60-90 px.
Rendered render_large(const rv::TargetBoard& board, double tilt, double roll, double blur,
                      double noise) {
  const rt::SyntheticCamera cam{1280, 1024, 1200.0, 639.5, 511.5};
  return rt::render_board_view(board, cam, 0.5, tilt, 20.0, roll, 639.5, 511.5, blur, noise);
}

struct Errors {
  double rms = 0.0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
};

Errors errors_of(const rv::TargetDetection& det, const Rendered& r) {
  Errors e;
  for (size_t i = 0; i < det.pixels.size(); ++i) {
    const Eigen::Vector2d d = det.pixels[i] - rt::apply_h(r.h, det.board_points[i].head<2>());
    e.rms += d.squaredNorm();
    e.mean += d;
  }
  const double n = static_cast<double>(std::max<size_t>(1, det.pixels.size()));
  e.rms = std::sqrt(e.rms / n);
  e.mean /= n;
  return e;
}

}  // namespace

// OpenCV 4.6 interpolates ChArUco corners +0.5 px off; ours must be unbiased (with the bug the
// mean error would be (0.5, 0.5)).
TEST(CharucoDetection, OffsetCorrectedAndAccurate) {
  const auto board = charuco_board();
  for (double tilt : {0.0, 40.0}) {
    const auto r = render_large(board, tilt, 5.0, 0.8, 2.0);
    const auto det = rv::detect_charuco_board(r.image, board);
    ASSERT_EQ(det.status, rv::DetectionStatus::kFound) << det.reason;
    EXPECT_EQ(det.pixels.size(), 24u);
    const Errors e = errors_of(det, r);
    EXPECT_LT(std::abs(e.mean.x()), 0.02) << "tilt " << tilt;
    EXPECT_LT(std::abs(e.mean.y()), 0.02) << "tilt " << tilt;
    EXPECT_LT(e.rms, 0.05) << "tilt " << tilt;
    EXPECT_GT(det.edge_blur_px, 0.7);
    EXPECT_LT(det.edge_blur_px, 1.0);
  }
}

TEST(CharucoDetection, PartialViewAndWrongBoard) {
  const auto board = charuco_board();
  auto r = render_large(board, 20.0, 0.0, 0.8, 1.0);
  // Cover the right third of the image.
  r.image(cv::Rect(r.image.cols * 2 / 3 - 60, 0, r.image.cols / 3 + 60, r.image.rows)).setTo(220);
  const auto det = rv::detect_charuco_board(r.image, board);
  ASSERT_EQ(det.status, rv::DetectionStatus::kPartial) << det.reason;
  EXPECT_LT(det.pixels.size(), 24u);
  EXPECT_GT(det.pixels.size(), 4u);
  EXPECT_FALSE(det.missing_marker_ids.empty());
  EXPECT_LT(errors_of(det, r).rms, 0.05);
  // A chessboard target given for a ChArUco image: rejected with the reason, no crash.
  const auto wrong = rv::detect_chessboard_board(r.image, charuco_board());
  EXPECT_EQ(wrong.status, rv::DetectionStatus::kRejected);
  EXPECT_EQ(wrong.reason, "target is not a chessboard");
}

// Ids follow the board, not OpenCV's scan order: an asymmetric board (8 x 5 squares) rotated by
// 180 deg in the image must still map every corner to its own board point.
TEST(ChessboardDetection, IdsFollowTheBoardUnderRotation) {
  const auto board = chessboard(8, 5);
  for (double roll : {10.0, 190.0}) {
    const auto r = render_large(board, 30.0, roll, 0.8, 2.0);
    const auto det = rv::detect_chessboard_board(r.image, board);
    ASSERT_EQ(det.status, rv::DetectionStatus::kFound) << det.reason;
    EXPECT_EQ(det.pixels.size(), 7u * 4u);
    const Errors e = errors_of(det, r);
    EXPECT_LT(e.rms, 0.05) << "roll " << roll;
    EXPECT_LT(std::abs(e.mean.x()), 0.02);
    EXPECT_LT(std::abs(e.mean.y()), 0.02);
  }
  // A mirrored chessboard is not detectable as such: its corner lattice is mirror-symmetric and
  // the mirrored colours equal the board turned by 180 deg, so it is a valid view (coded boards
  // do not decode mirrored; calibrate_intrinsics rejects mirrored poses).
}

// A board sliding out of the image across its right or bottom border: every corner the detector
// returns must lie where the board point projects, however little of its tag is left in the
// image. (Tags whose white quiet zone or black border is cut by the border used to come back up
// to 10 px off with a 0.01 px sigma: the edge fit, its window clamped to the image, locked onto
// the image border instead of the tag's edge.)
TEST(AprilTagBoardDetection, TagsCutByTheImageBorderAreRightOrAbsent) {
  const auto board = tag_board();
  rv::AprilTagDetector detector;
  const rt::SyntheticCamera cam{640, 512, 600.0, 319.5, 255.5};
  int corners_checked = 0;
  int views = 0;
  double nearest_to_border = 1e9;  // px, of the corners returned
  for (int side = 0; side < 2; ++side) {
    for (double shift = 150.0; shift <= 330.0; shift += 6.1) {
      const double u = side == 0 ? 319.5 + shift : 319.5;
      const double v = side == 0 ? 255.5 : 255.5 + 0.8 * shift;
      const auto r = rt::render_board_view(board, cam, 0.5, 25.0, 30.0, 5.0, u, v, 0.8, 2.0);
      const auto det = rv::detect_apriltag_board(r.image, board, detector);
      ++views;
      for (size_t i = 0; i < det.pixels.size(); ++i) {
        const auto p = rv::corner_point(board, det.corner_ids[i]);
        ASSERT_TRUE(p.has_value());
        const Eigen::Vector2d truth = rt::apply_h(r.h, p->head<2>());
        ++corners_checked;
        nearest_to_border = std::min(
            {nearest_to_border, cam.width - 0.5 - truth.x(), cam.height - 0.5 - truth.y()});
        EXPECT_LT((det.pixels[i] - truth).norm(), 0.25)
            << "corner " << det.corner_ids[i] << " at (" << det.pixels[i].transpose() << "), true ("
            << truth.transpose() << "), board centre at (" << u << ", " << v << ")";
      }
    }
  }
  // The sweep must have exercised the border: some corners, but far fewer than all, and tags
  // whose quiet zone just fits (a cell of the tag is 6 px here) kept.
  EXPECT_GT(corners_checked, 200);
  EXPECT_LT(corners_checked, views * 48);
  EXPECT_LT(nearest_to_border, 12.0);
}
// Tags too small for the edge-fit refinement are detected with the library's corners alone; a
// later frame of the same still view cannot refine them either, so it is detected in full
// instead of reported as "moved" (the live Gantry-Tau's small boards at the edge of a view).
TEST(AprilTagBoardDetection, ViewOfUnrefinedTagsIsDetectedAgainInFull) {
  const auto board = tag_board();
  const rt::SyntheticCamera cam{640, 512, 600.0, 319.5, 255.5};
  rv::AprilTagDetector detector(rv::detector_options_for(board));
  // 1.0 m: no tag refined; 0.9 m: one of the twelve.
  for (const auto& [distance, refined] : {std::pair{1.0, 0u}, std::pair{0.9, 1u}}) {
    // An init-capture: clang 14 cannot capture a structured binding.
    const auto view = [&, distance = distance](unsigned seed) {
      return rt::render_board_view(board, cam, distance, 35.0, 20.0, 5.0, 319.5, 255.5, 0.8, 2.0,
                                   seed);
    };
    const rv::TargetDetection first = rv::detect_target(view(1).image, board, detector);
    ASSERT_EQ(first.status, rv::DetectionStatus::kFound) << first.reason;
    ASSERT_EQ(first.corner_groups.size(), refined) << "at " << distance << " m";
    const rv::TargetDetection again =
        rv::redetect_apriltag_board(view(2).image, board, first, detector);
    EXPECT_EQ(again.status, rv::DetectionStatus::kFound) << again.reason;
    EXPECT_EQ(again.corner_ids, first.corner_ids);
    for (std::size_t i = 0; i < again.pixels.size() && i < first.pixels.size(); ++i)
      EXPECT_LT((again.pixels[i] - first.pixels[i]).norm(), 1.0) << "corner " << i;
  }
}
