// Views files, truth files and the PDF drawing.
#include "robocal/vision/render_io.hpp"
#include "robocal/vision/target_io.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace rv = robocal::vision;

namespace {
std::string views_error(const std::string& text, int targets = 1) {
  try {
    rv::parse_render_views(text, "views.yaml", targets);
  } catch (const rv::FileFormatError& e) {
    return e.what();
  }
  return "no error";
}
}  // namespace

TEST(RenderViews, Parses) {
  const auto views = rv::parse_render_views(
      "views:\n"
      "  - name: a\n"
      "    poses: [{rvec: [0, 0, 1.5707963267948966], t: [0.1, 0.2, 0.5]}]\n"
      "    occluders: [{disc: [10, 20, 5], level: 3}, {rectangle: [1, 2, 3, 4], level: 200}]\n"
      "    seed: 9\n"
      "  - poses: [{rvec: [0, 0, 0], t: [0, 0, 1]}]\n",
      "views.yaml", 1);
  ASSERT_EQ(views.size(), 2u);
  EXPECT_EQ(views[0].name, "a");
  EXPECT_EQ(views[0].seed, 9u);
  EXPECT_EQ(views[1].name, "view001");
  EXPECT_EQ(views[1].seed, 2u);
  const Eigen::Vector3d p = views[0].camera_T_board[0] * Eigen::Vector3d(1, 0, 0);
  EXPECT_LT((p - Eigen::Vector3d(0.1, 1.2, 0.5)).norm(), 1e-12);
  ASSERT_EQ(views[0].occluders.size(), 2u);
  EXPECT_EQ(views[0].occluders[1].shape, rv::Occluder::Shape::kRectangle);
  EXPECT_EQ(views[0].occluders[1].half_size, Eigen::Vector2d(3, 4));
}

TEST(RenderViews, ErrorsNameFileAndLine) {
  EXPECT_EQ(views_error("views:\n  - poses: [{rvec: [0, 0], t: [0, 0, 1]}]\n"),
            "views.yaml:2: 'rvec' must have 3 numbers (got 2)");
  EXPECT_EQ(views_error("views:\n  - poses: [{rvec: [0, 0, 0], t: [0, 0, 1]}]\n", 2),
            "views.yaml:2: view 'view000' has 1 poses but there are 2 targets");
  EXPECT_EQ(views_error("views: []\n"), "views.yaml:1: 'views' must be a non-empty list");
  EXPECT_EQ(views_error("views:\n  - poses: [{rvec: [0, 0, 0], t: [0, 0, 1]}]\n"
                        "    occluders: [{disc: [1, 2, -3], level: 0}]\n"),
            "views.yaml:3: disc must be [cx, cy, radius > 0]");
}

TEST(RenderTruth, WriteAndReadBack) {
  const auto cam = rv::make_camera(rv::CameraKind::kFisheyeKB4, 320, 240, 200, 200, 159.5, 119.5,
                                   {0.01, 0, 0, 0});
  rv::TargetSpec s;
  s.kind = rv::TargetKind::kChessboard;
  s.cols = 4;
  s.rows = 3;
  s.square_size = 0.02;
  s.name = "chess";
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(-0.04, -0.03, 0.3);
  pose.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 0).normalized()).toRotationMatrix();
  const std::vector<rv::RenderTarget> targets = {{rv::build_target(s), pose}};
  rv::RenderOptions opt;
  const auto corners = rv::corner_truth(cam, targets, opt);
  const auto path = std::filesystem::temp_directory_path() / "robocal_truth_test.json";
  std::ofstream(path) << rv::render_truth_json("img.png", cam, targets, opt, corners);
  const rv::RenderTruth back = rv::load_render_truth(path);
  std::filesystem::remove(path);
  EXPECT_EQ(back.image, "img.png");
  EXPECT_EQ(back.camera.params, cam.params);
  ASSERT_EQ(back.camera_T_board.size(), 1u);
  EXPECT_LT((back.camera_T_board[0].matrix() - pose.matrix()).norm(), 1e-14);
  ASSERT_EQ(back.corners.size(), corners.size());
  for (size_t i = 0; i < corners.size(); ++i) {
    EXPECT_EQ(back.corners[i].id, corners[i].id);
    EXPECT_EQ(back.corners[i].visible, corners[i].visible);
    EXPECT_EQ(back.corners[i].pixel, corners[i].pixel);  // 17 significant digits: exact
  }
}

TEST(TargetPdf, XrefOffsetsPointAtObjects) {
  rv::TargetSpec s;
  s.kind = rv::TargetKind::kChessboard;
  s.cols = 3;
  s.rows = 2;
  s.square_size = 0.0254;  // one inch = 72 pt
  s.margin = 0.0254;
  const std::string pdf = rv::target_to_pdf(rv::build_target(s));
  EXPECT_NE(pdf.find("/MediaBox [0 0 360.0000 288.0000]"), std::string::npos);
  // First square (top-left black) sits one inch in from the left and top.
  EXPECT_NE(pdf.find("72.0000 144.0000 72.0000 72.0000 re f"), std::string::npos);
  const size_t xref = pdf.find("xref\n");
  ASSERT_NE(xref, std::string::npos);
  const size_t startxref = pdf.find("startxref\n");
  EXPECT_EQ(std::stoul(pdf.substr(startxref + 10)), xref);
  size_t pos = pdf.find("0000000000 65535 f \n", xref) + 20;
  for (int obj = 1; obj <= 4; ++obj, pos += 20) {
    const size_t off = std::stoul(pdf.substr(pos, 10));
    EXPECT_EQ(pdf.substr(off, std::to_string(obj).size() + 6), std::to_string(obj) + " 0 obj");
  }
}
