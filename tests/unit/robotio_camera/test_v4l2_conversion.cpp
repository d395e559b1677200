// V4L2 format conversion on small raw buffers (testdata/camera/v4l2, generated from one known
// colour image by make_v4l2_buffers.cpp there), and live capture when a device exists.
#include "robocal/robotio/camera_v4l2.hpp"

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace robocal::robotio {
namespace {

const std::string kDir = std::string(ROBOCAL_TESTDATA_DIR) + "/camera/v4l2/";

std::vector<unsigned char> read_bytes(const std::string& name) {
  std::ifstream in(kDir + name, std::ios::binary);
  EXPECT_TRUE(in.good()) << kDir + name;
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The truth image (binary PPM "P6\n48 32\n255\n"), as RGB bytes.
cv::Mat truth_rgb() {
  const std::vector<unsigned char> ppm = read_bytes("truth.ppm");
  const std::string header = "P6\n48 32\n255\n";
  EXPECT_EQ(std::string(ppm.begin(), ppm.begin() + static_cast<long>(header.size())), header);
  cv::Mat rgb(32, 48, CV_8UC3);
  std::copy(ppm.begin() + static_cast<long>(header.size()), ppm.end(), rgb.data);
  return rgb;
}

V4l2RawFrame raw(const std::string& fourcc, const std::vector<unsigned char>& bytes,
                 int bytes_per_line = 0) {
  V4l2RawFrame frame;
  frame.fourcc = fourcc;
  frame.width = 48;
  frame.height = 32;
  frame.bytes_per_line = bytes_per_line;
  frame.data = bytes;
  return frame;
}

TEST(V4l2Conversion, GreyWithPaddedRowsIsCopiedExactly) {
  const std::vector<unsigned char> bytes = read_bytes("grey_48x32_bpl56.raw");
  ASSERT_EQ(bytes.size(), 56U * 32U);
  const cv::Mat grey = convert_v4l2_frame(raw("GREY", bytes, 56), V4l2Output::kGrey, "usb0");
  ASSERT_EQ(grey.type(), CV_8UC1);
  cv::Mat channels[3];
  cv::split(truth_rgb(), channels);
  EXPECT_EQ(cv::norm(grey, channels[0], cv::NORM_INF), 0.0);  // the generator's red channel
}

TEST(V4l2Conversion, YuyvLumaIsTheBt601LumaOfTheTruth) {
  const cv::Mat grey =
      convert_v4l2_frame(raw("YUYV", read_bytes("yuyv_48x32.raw")), V4l2Output::kGrey, "usb0");
  const cv::Mat rgb = truth_rgb();
  double worst = 0.0;
  for (int y = 0; y < 32; ++y) {
    for (int x = 0; x < 48; ++x) {
      const cv::Vec3b& p = rgb.at<cv::Vec3b>(y, x);
      // BT.601 studio-range luma, rounded once by the generator.
      const double luma = 16.0 + (65.481 * p[0] + 128.553 * p[1] + 24.966 * p[2]) / 255.0;
      worst = std::max(worst, std::abs(grey.at<unsigned char>(y, x) - luma));
    }
  }
  EXPECT_LE(worst, 0.5 + 1e-9);
}

TEST(V4l2Conversion, YuyvColourRecoversTheTruthWithinQuantisation) {
  const cv::Mat bgr =
      convert_v4l2_frame(raw("YUYV", read_bytes("yuyv_48x32.raw")), V4l2Output::kColour, "usb0");
  ASSERT_EQ(bgr.type(), CV_8UC3);
  const cv::Mat rgb = truth_rgb();
  // Y, Cb, Cr each rounded to 8 bits (+-0.5): R, G, B off by at most 1.164*0.5 + 2.017*0.5
  // (blue, the largest) = 1.59 before rounding the result, so 2 DN at most. The shared chroma of
  // a pair costs nothing: both pixels of a pair have the same colour in the truth, differing by
  // luma only (+3 DN on each channel of the odd pixel, which is grey and so pure luma).
  double worst = 0.0;
  for (int y = 0; y < 32; ++y) {
    for (int x = 0; x < 48; ++x) {
      for (int c = 0; c < 3; ++c) {
        worst = std::max(worst, std::abs(static_cast<double>(bgr.at<cv::Vec3b>(y, x)[2 - c]) -
                                         rgb.at<cv::Vec3b>(y, x)[c]));
      }
    }
  }
  EXPECT_LE(worst, 2.0);
  EXPECT_GT(cv::norm(bgr), 0.0);
}

// JPEG at quality 95 is lossy: the decoded image is compared with the truth by its error, which
// a wrong colour order, a row shift or a wrong decode would blow up (tens of DN).
void expect_jpeg_close_to_truth(const std::string& file) {
  const cv::Mat bgr =
      convert_v4l2_frame(raw("MJPG", read_bytes(file)), V4l2Output::kColour, "usb0");
  ASSERT_EQ(bgr.type(), CV_8UC3);
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  const cv::Mat truth = truth_rgb();
  const double mean_error = cv::norm(rgb, truth, cv::NORM_L1) / (48.0 * 32.0 * 3.0);
  EXPECT_LT(mean_error, 3.0) << file;
  const cv::Mat grey = convert_v4l2_frame(raw("MJPG", read_bytes(file)), V4l2Output::kGrey, "usb0");
  ASSERT_EQ(grey.type(), CV_8UC1);
  double grey_error = 0.0;
  for (int y = 0; y < 32; ++y) {
    for (int x = 0; x < 48; ++x) {
      const cv::Vec3b& p = truth.at<cv::Vec3b>(y, x);
      const double luma = 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2];  // JFIF full range
      grey_error += std::abs(grey.at<unsigned char>(y, x) - luma);
    }
  }
  EXPECT_LT(grey_error / (48.0 * 32.0), 2.0) << file;
}

TEST(V4l2Conversion, MjpegDecodesCloseToTheTruth) {
  expect_jpeg_close_to_truth("mjpeg_48x32.jpg");
}

TEST(V4l2Conversion, MjpegWithoutHuffmanTablesAsUvcSendsItDecodes) {
  expect_jpeg_close_to_truth("mjpeg_48x32_nodht.jpg");
}

void expect_incomplete(const V4l2RawFrame& frame, const std::string& fragment) {
  try {
    (void)convert_v4l2_frame(frame, V4l2Output::kGrey, "usb0");
    FAIL() << "accepted: " << fragment;
  } catch (const CameraError& error) {
    EXPECT_EQ(error.kind(), CameraError::Kind::kIncompleteFrame) << error.what();
    EXPECT_NE(std::string(error.what()).find("usb0: " + fragment), std::string::npos)
        << error.what();
  }
}

TEST(V4l2Conversion, TruncatedOrWrongSizeBuffersAreIncompleteFramesNamingTheCamera) {
  std::vector<unsigned char> yuyv = read_bytes("yuyv_48x32.raw");
  yuyv.resize(yuyv.size() - 10);
  expect_incomplete(raw("YUYV", yuyv), "YUYV frame of 3062 bytes, 48x32 needs 3072 (truncated)");
  std::vector<unsigned char> jpeg = read_bytes("mjpeg_48x32.jpg");
  jpeg.resize(jpeg.size() / 2);
  expect_incomplete(raw("MJPG", jpeg), "MJPEG frame of");
  // A whole JPEG of another size than the stream's.
  const std::vector<unsigned char> whole = read_bytes("mjpeg_48x32.jpg");
  V4l2RawFrame wrong = raw("MJPG", whole);
  wrong.width = 64;
  expect_incomplete(wrong, "MJPEG frame decodes to 48x32, the stream is 64x32");
  expect_incomplete(raw("GREY", read_bytes("grey_48x32_bpl56.raw"), 40),
                    "GREY row of 40 bytes, a 48 pixel row needs 48");
  try {
    (void)convert_v4l2_frame(raw("H264", yuyv), V4l2Output::kGrey, "usb0");
    FAIL() << "H264 accepted";
  } catch (const CameraError& error) {
    EXPECT_EQ(error.kind(), CameraError::Kind::kUnsupported);
  }
}

TEST(V4l2Camera, MissingDeviceIsNotFoundNamingIt) {
  try {
    V4l2Camera camera("/dev/video-robocal-none", "usb0");
    FAIL() << "opened a device that does not exist";
  } catch (const CameraError& error) {
    EXPECT_EQ(error.kind(), CameraError::Kind::kNotFound);
    EXPECT_NE(std::string(error.what()).find("usb0: cannot open /dev/video-robocal-none"),
              std::string::npos)
        << error.what();
  }
}

TEST(V4l2Camera, LiveCaptureFromTheFirstDevice) {
  const std::vector<CameraInfo> cameras = discover_v4l2_cameras();
  if (cameras.empty()) {
    GTEST_SKIP() << "no V4L2 capture device (/dev/video*) on this machine: live capture not "
                    "tested; conversions are tested on recorded buffers above";
  }
  V4l2Camera camera(cameras.front().id, "usb0");
  EXPECT_FALSE(camera.info().pixel_formats.empty());
  camera.start(TriggerMode::kSoftware);
  std::int64_t last = 0;
  for (int i = 0; i < 3; ++i) {
    const Frame frame = camera.grab(std::chrono::milliseconds(3000));
    EXPECT_EQ(frame.image.cols, camera.region().width);
    EXPECT_EQ(frame.image.rows, camera.region().height);
    EXPECT_GT(frame.timestamp_ns, last);
    last = frame.timestamp_ns;
  }
  camera.stop();
}

}  // namespace
}  // namespace robocal::robotio
