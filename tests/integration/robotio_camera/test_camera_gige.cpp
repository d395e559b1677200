// Camera sources over the real GigE Vision protocol: rendered frames served by Aravis' fake
// cameras on two loopback addresses, read back through AravisCamera (run_in_netns.sh).
#include "robocal/robotio/camera_aravis.hpp"
#include "robocal/robotio/camera_fake_gige.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/target_io.hpp"

#include "netns_skip.hpp"

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include <chrono>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace robocal::robotio {
namespace {

using std::chrono::milliseconds;
constexpr milliseconds kGrabTimeout{3000};

// Rendered views of the AprilTag test board, different poses per camera, 8-bit or 16-bit.
std::vector<cv::Mat> rendered_views(int camera_index, int count, int bit_depth) {
  const vision::CameraModel camera =
      vision::load_camera_file(std::string(ROBOCAL_TESTDATA_DIR) + "/vision/camera_640x480.yaml");
  const vision::TargetBoard board =
      vision::load_target_file(std::string(ROBOCAL_TESTDATA_DIR) + "/vision/apriltag_4x3.yaml");
  const vision::CameraRays rays = vision::precompute_rays(camera);
  std::vector<cv::Mat> images;
  for (int i = 0; i < count; ++i) {
    vision::RenderTarget target{board, Eigen::Isometry3d::Identity()};
    target.camera_T_board = vision::camera_T_board_look_at(
        Eigen::Vector3d(0.05 * (i - count / 2.0), 0.03 * camera_index, -0.45),
        Eigen::Vector3d(0.08, 0.06, 0.0), Eigen::Vector3d(0.0, 1.0, 0.0));
    vision::RenderOptions options;
    options.read_noise = 1.5;
    options.blur_sigma = 0.6;
    options.bit_depth = bit_depth;
    options.seed = static_cast<std::uint64_t>(100 * camera_index + i + 1);
    images.push_back(vision::render(rays, {target}, options).image);
  }
  return images;
}

// A fake camera serving a list of images in turn, remembering what the client last asked for.
struct ServedCamera {
  std::vector<cv::Mat> images;
  std::mutex mutex;
  FakeFrameRequest last_request;
  std::unique_ptr<FakeGigECamera> server;

  ServedCamera(const std::string& address, const std::string& serial, std::vector<cv::Mat> views)
      : images(std::move(views)) {
    server = std::make_unique<FakeGigECamera>(address, serial, [this](const FakeFrameRequest& r) {
      {
        const std::lock_guard lock(mutex);
        last_request = r;
      }
      const cv::Mat& full = images[r.frame_index % images.size()];
      return full(cv::Rect(r.region.x, r.region.y, r.region.width, r.region.height)).clone();
    });
  }
  FakeFrameRequest request() {
    const std::lock_guard lock(mutex);
    return last_request;
  }
};

bool identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

TEST(GigECamera, TwoCamerasOnTheirOwnAddressesStreamRenderedFramesBitExact) {
  SKIP_WITHOUT_NETNS();
  constexpr int kViews = 4;
  constexpr int kFrames = 8;
  ServedCamera served0("127.0.0.1", "ROBOCAL-A", rendered_views(0, kViews, 8));
  ServedCamera served1("127.0.0.2", "ROBOCAL-B", rendered_views(1, kViews, 8));
  AravisCamera cam0("ROBOCAL-A", "cam0");
  AravisCamera cam1("ROBOCAL-B", "cam1");
  for (AravisCamera* camera : {&cam0, &cam1}) {
    camera->set_pixel_format("Mono8");
    camera->set_region({0, 0, 640, 480});
    camera->start(TriggerMode::kSoftware);
  }
  std::int64_t last_stamp[2] = {0, 0};
  for (int i = 0; i < kFrames; ++i) {
    // Interleaved, as capture does: each camera's frame i is the view it served i-th.
    const Frame frame0 = cam0.grab(kGrabTimeout);
    const Frame frame1 = cam1.grab(kGrabTimeout);
    EXPECT_TRUE(identical(frame0.image, served0.images[i % kViews])) << "cam0 frame " << i;
    EXPECT_TRUE(identical(frame1.image, served1.images[i % kViews])) << "cam1 frame " << i;
    EXPECT_EQ(frame0.pixel_format, "Mono8");
    EXPECT_GT(frame0.timestamp_ns, last_stamp[0]) << "cam0 frame " << i;
    EXPECT_GT(frame1.timestamp_ns, last_stamp[1]) << "cam1 frame " << i;
    last_stamp[0] = frame0.timestamp_ns;
    last_stamp[1] = frame1.timestamp_ns;
  }
  // The two views differ, so a swap of cameras would have failed above.
  EXPECT_FALSE(identical(served0.images[0], served1.images[0]));
  EXPECT_EQ(served0.server->frames_served(), static_cast<std::uint64_t>(kFrames));
  EXPECT_EQ(served1.server->frames_served(), static_cast<std::uint64_t>(kFrames));
  EXPECT_EQ(served0.server->last_error(), "");
  const StreamStatistics stats = cam0.statistics();
  EXPECT_EQ(stats.completed_frames, static_cast<std::uint64_t>(kFrames));
  EXPECT_EQ(stats.failed_frames, 0U);
  EXPECT_EQ(stats.missing_packets, 0U);
}

TEST(GigECamera, ExposureAndGainRoundTripToTheSensor) {
  SKIP_WITHOUT_NETNS();
  ServedCamera served0("127.0.0.1", "ROBOCAL-A", rendered_views(0, 1, 8));
  ServedCamera served1("127.0.0.2", "ROBOCAL-B", rendered_views(1, 1, 8));
  AravisCamera cam0("ROBOCAL-A", "cam0");
  AravisCamera cam1("127.0.0.2", "cam1");  // by address this time
  cam0.set_exposure_us(4000.0);
  cam0.set_gain(3.0);
  cam1.set_exposure_us(12000.0);
  cam1.set_gain(7.0);
  EXPECT_DOUBLE_EQ(cam0.exposure_us(), 4000.0);
  EXPECT_DOUBLE_EQ(cam0.gain(), 3.0);
  EXPECT_DOUBLE_EQ(cam1.exposure_us(), 12000.0);
  EXPECT_DOUBLE_EQ(cam1.gain(), 7.0);
  // ... and the sensor side saw the same values when it made the next frame.
  cam0.set_region({0, 0, 640, 480});
  cam1.set_region({0, 0, 640, 480});
  cam0.start(TriggerMode::kSoftware);
  cam1.start(TriggerMode::kSoftware);
  (void)cam0.grab(kGrabTimeout);
  (void)cam1.grab(kGrabTimeout);
  EXPECT_DOUBLE_EQ(served0.request().exposure_us, 4000.0);
  EXPECT_DOUBLE_EQ(served0.request().gain, 3.0);
  EXPECT_DOUBLE_EQ(served1.request().exposure_us, 12000.0);
  EXPECT_DOUBLE_EQ(served1.request().gain, 7.0);
  // Out of range is refused with the range.
  try {
    cam0.set_exposure_us(-5.0);
    FAIL() << "negative exposure accepted";
  } catch (const CameraError& error) {
    EXPECT_EQ(error.kind(), CameraError::Kind::kUnsupported);
    EXPECT_NE(std::string(error.what()).find("cam0: exposure"), std::string::npos) << error.what();
  }
}

TEST(GigECamera, DiscoveryDescribesBothCameras) {
  SKIP_WITHOUT_NETNS();
  ServedCamera served0("127.0.0.1", "ROBOCAL-A", rendered_views(0, 1, 8));
  ServedCamera served1("127.0.0.2", "ROBOCAL-B", rendered_views(1, 1, 8));
  const std::vector<CameraInfo> found = discover_aravis_cameras();
  int seen = 0;
  for (const CameraInfo& info : found) {
    if (info.serial == "ROBOCAL-A") {
      EXPECT_EQ(info.address, "127.0.0.1");
      ++seen;
    }
    if (info.serial == "ROBOCAL-B") {
      EXPECT_EQ(info.address, "127.0.0.2");
      ++seen;
    }
  }
  EXPECT_EQ(seen, 2);
  AravisCamera camera("ROBOCAL-B", "cam1");
  const CameraInfo info = camera.info();
  EXPECT_EQ(info.driver, "aravis");
  EXPECT_EQ(info.serial, "ROBOCAL-B");
  EXPECT_EQ(info.sensor_width, 2048);
  EXPECT_EQ(info.sensor_height, 2048);
  EXPECT_FALSE(info.model.empty());
  const auto has = [&](const std::string& f) {
    return std::find(info.pixel_formats.begin(), info.pixel_formats.end(), f) !=
           info.pixel_formats.end();
  };
  EXPECT_TRUE(has("Mono8"));
  EXPECT_TRUE(has("Mono16"));
}

TEST(GigECamera, Mono16FramesAndARegionOfInterestArriveBitExact) {
  SKIP_WITHOUT_NETNS();
  ServedCamera served("127.0.0.2", "ROBOCAL-B", rendered_views(1, 2, 16));
  AravisCamera camera("ROBOCAL-B", "cam1");
  camera.set_pixel_format("Mono16");
  const Region region{64, 32, 320, 240};
  camera.set_region(region);
  EXPECT_EQ(camera.region(), region);
  camera.start(TriggerMode::kSoftware);
  for (int i = 0; i < 2; ++i) {
    const Frame frame = camera.grab(kGrabTimeout);
    const cv::Mat expected =
        served.images[i](cv::Rect(region.x, region.y, region.width, region.height));
    EXPECT_TRUE(identical(frame.image, expected)) << "frame " << i;
    EXPECT_EQ(frame.image.type(), CV_16UC1);
  }
}

TEST(GigECamera, FreeRunningStreamDeliversIncreasingTimestamps) {
  SKIP_WITHOUT_NETNS();
  ServedCamera served("127.0.0.1", "ROBOCAL-A", rendered_views(0, 3, 8));
  AravisCamera camera("ROBOCAL-A", "cam0");
  camera.set_region({0, 0, 640, 480});
  camera.start(TriggerMode::kFreeRunning);
  std::int64_t last = 0;
  for (int i = 0; i < 5; ++i) {
    const Frame frame = camera.grab(kGrabTimeout);
    EXPECT_GT(frame.timestamp_ns, last);
    last = frame.timestamp_ns;
    // Whatever frame it is, it is one of the served views, unchanged.
    bool matches = false;
    for (const cv::Mat& view : served.images) {
      matches = matches || identical(frame.image, view);
    }
    EXPECT_TRUE(matches) << "frame " << i;
  }
  camera.stop();
}

TEST(GigECamera, UnknownSerialNamesItAndTheCamerasFound) {
  SKIP_WITHOUT_NETNS();
  ServedCamera served("127.0.0.1", "ROBOCAL-A", rendered_views(0, 1, 8));
  try {
    AravisCamera camera("NO-SUCH-SERIAL", "cam7");
    FAIL() << "opened a camera that does not exist";
  } catch (const CameraError& error) {
    EXPECT_EQ(error.kind(), CameraError::Kind::kNotFound);
    const std::string text = error.what();
    EXPECT_NE(text.find("cam7"), std::string::npos) << text;
    EXPECT_NE(text.find("NO-SUCH-SERIAL"), std::string::npos) << text;
    EXPECT_NE(text.find("ROBOCAL-A"), std::string::npos) << text;
  }
}

TEST(GigECamera, PixelFormatTheCameraLacksIsRefusedNamingTheCamera) {
  SKIP_WITHOUT_NETNS();
  ServedCamera served("127.0.0.1", "ROBOCAL-A", rendered_views(0, 1, 8));
  AravisCamera camera("ROBOCAL-A", "cam0");
  try {
    camera.set_pixel_format("YUV422_8");
    FAIL() << "accepted a pixel format the fake camera lacks";
  } catch (const CameraError& error) {
    EXPECT_EQ(error.kind(), CameraError::Kind::kUnsupported);
    const std::string text = error.what();
    EXPECT_NE(text.find("cam0: pixel format YUV422_8 not offered"), std::string::npos) << text;
    EXPECT_NE(text.find("Mono8"), std::string::npos) << text;  // what it has
  }
  EXPECT_EQ(camera.pixel_format(), "Mono8");  // unchanged
}

TEST(GigECamera, SlowCameraTimesOutAndStillAnswers) {
  SKIP_WITHOUT_NETNS();
  const cv::Mat view = rendered_views(0, 1, 8).front();
  FakeGigECamera server("127.0.0.1", "ROBOCAL-SLOW", [&](const FakeFrameRequest& r) {
    std::this_thread::sleep_for(milliseconds(800));
    return view(cv::Rect(r.region.x, r.region.y, r.region.width, r.region.height)).clone();
  });
  AravisCamera camera("ROBOCAL-SLOW", "cam0");
  camera.set_region({0, 0, 640, 480});
  camera.start(TriggerMode::kSoftware);
  const auto begin = std::chrono::steady_clock::now();
  try {
    (void)camera.grab(milliseconds(200));
    FAIL() << "a frame arrived before the slow camera made it";
  } catch (const CameraError& error) {
    EXPECT_EQ(error.kind(), CameraError::Kind::kTimeout) << error.what();
    EXPECT_NE(std::string(error.what()).find("cam0: no frame within 200 ms"), std::string::npos)
        << error.what();
  }
  EXPECT_LT(std::chrono::steady_clock::now() - begin, std::chrono::seconds(5));
}

TEST(GigECamera, CameraDisconnectedWhileStreamingIsReportedAsDisconnected) {
  SKIP_WITHOUT_NETNS();
  ServedCamera served("127.0.0.2", "ROBOCAL-B", rendered_views(1, 2, 8));
  AravisCamera camera("ROBOCAL-B", "cam1");
  camera.set_region({0, 0, 640, 480});
  camera.start(TriggerMode::kSoftware);
  const Frame first = camera.grab(kGrabTimeout);
  ASSERT_TRUE(identical(first.image, served.images[0]));
  served.server->disconnect();  // cable pulled
  const auto begin = std::chrono::steady_clock::now();
  try {
    (void)camera.grab(milliseconds(500));
    FAIL() << "grabbed from a camera that is gone";
  } catch (const CameraError& error) {
    EXPECT_EQ(error.kind(), CameraError::Kind::kDisconnected) << error.what();
    EXPECT_NE(std::string(error.what()).find("cam1: "), std::string::npos) << error.what();
  }
  EXPECT_LT(std::chrono::steady_clock::now() - begin, std::chrono::seconds(10));
  // The frame already taken is intact.
  EXPECT_TRUE(identical(first.image, served.images[0]));
}

}  // namespace
}  // namespace robocal::robotio
