// The capture's PNG writer against OpenCV's independent decoder: every supported image type comes
// back bit for bit, and the file is no larger than storing the pixels raw.
#include "robocal/robotio/png_encode.hpp"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

// A camera-like image: a smooth gradient, a bright square, and noise (the case the encoder's
// Huffman-only choice is made for).
cv::Mat camera_like(int type, std::uint32_t seed) {
  cv::Mat image(97, 131, type);  // odd sizes: no row padding assumption
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 3.0);
  const double full = CV_MAT_DEPTH(type) == CV_16U ? 65535.0 : 255.0;
  const int channels = CV_MAT_CN(type);
  for (int r = 0; r < image.rows; ++r)
    for (int c = 0; c < image.cols; ++c)
      for (int k = 0; k < channels; ++k) {
        double v = full * (0.2 + 0.5 * c / image.cols + 0.1 * k);
        if (r > 30 && r < 60 && c > 40 && c < 90) v = 0.95 * full;
        v = std::clamp(v + noise(rng) * full / 255.0, 0.0, full);
        if (CV_MAT_DEPTH(type) == CV_16U)
          image.ptr<std::uint16_t>(r)[c * channels + k] = static_cast<std::uint16_t>(v);
        else
          image.ptr<std::uint8_t>(r)[c * channels + k] = static_cast<std::uint8_t>(v);
      }
  return image;
}

class PngRoundTrip : public ::testing::TestWithParam<int> {};

TEST_P(PngRoundTrip, DecodesToTheSamePixels) {
  const cv::Mat image = camera_like(GetParam(), 7);
  for (const int level : {0, 1, 9}) {
    const std::string png = robocal::robotio::encode_png(image, level, "test image");
    ASSERT_GT(png.size(), 8U);
    EXPECT_EQ(png.substr(1, 3), "PNG");
    const std::vector<unsigned char> bytes(png.begin(), png.end());
    const cv::Mat back = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(back.empty()) << "level " << level;
    ASSERT_EQ(back.type(), image.type()) << "level " << level;
    ASSERT_EQ(back.size(), image.size());
    EXPECT_EQ(cv::norm(back, image, cv::NORM_INF), 0.0) << "level " << level;
    if (level > 0) {
      EXPECT_LT(png.size(), image.total() * image.elemSize()) << "level " << level;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Types, PngRoundTrip,
                         ::testing::Values(CV_8UC1, CV_16UC1, CV_8UC3, CV_16UC3, CV_8UC4));

TEST(PngEncode, ANonContiguousRegionIsWrittenRowByRow) {
  const cv::Mat image = camera_like(CV_8UC1, 3);
  const cv::Mat region = image(cv::Rect(10, 5, 64, 40));
  ASSERT_FALSE(region.isContinuous());
  const std::string png = robocal::robotio::encode_png(region, 1, "region");
  const cv::Mat back =
      cv::imdecode(std::vector<unsigned char>(png.begin(), png.end()), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(back.size(), region.size());
  EXPECT_EQ(cv::norm(back, region, cv::NORM_INF), 0.0);
}

TEST(PngEncode, AnEmptyImageIsRefusedWithItsName) {
  try {
    (void)robocal::robotio::encode_png(cv::Mat(), 1, "poses/pose_003/cam1_0.png");
    FAIL() << "an empty image was encoded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("poses/pose_003/cam1_0.png"), std::string::npos)
        << e.what();
  }
}

}  // namespace
