// Generates the raw V4L2 buffers of tests/unit/robotio_camera/test_v4l2_conversion.cpp from one
// known 48x32 colour image, so the conversion tests compare against an independent truth.
// Build and run (from this folder):
//   g++ -std=c++20 make_v4l2_buffers.cpp $(pkg-config --cflags --libs opencv4) -o /tmp/mk &&
//   /tmp/mk
// Writes: truth.ppm (the colour image), grey_48x32_bpl56.raw (GREY, 56 bytes per row, padding
// 0xAA), yuyv_48x32.raw (YUYV, BT.601 limited range, computed here with the standard RGB->YCbCr
// equations), mjpeg_48x32.jpg (baseline JPEG, quality 95) and mjpeg_48x32_nodht.jpg (the same
// without its Huffman tables, as many UVC cameras send MJPEG).
#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <cstdint>
#include <fstream>
#include <vector>

namespace {
constexpr int kWidth = 48;
constexpr int kHeight = 32;

// The truth: smooth colour ramps, a dark square and a bright bar; the colour is the same on both
// pixels of each horizontal pair (YUYV shares chroma between them), luma varies per pixel.
void truth_rgb(int x, int y, int rgb[3]) {
  const int pair = x / 2;
  rgb[0] = 40 + 8 * pair;
  rgb[1] = 30 + 6 * y;
  rgb[2] = 200 - 5 * pair - 2 * y;
  if (pair >= 8 && pair < 14 && y >= 8 && y < 20) {
    rgb[0] = 25;
    rgb[1] = 20;
    rgb[2] = 30;
  }
  if (y >= 24 && y < 28) {
    rgb[0] = 235;
    rgb[1] = 230;
    rgb[2] = 210;
  }
  for (int c = 0; c < 3; ++c) {
    rgb[c] += (x % 2) * 3;  // luma detail inside a pair
  }
}

unsigned char byte(double v) {
  return static_cast<unsigned char>(std::lround(std::fmin(255, std::fmax(0, v))));
}

void write(const char* path, const std::vector<unsigned char>& bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}
}  // namespace

int main() {
  cv::Mat bgr(kHeight, kWidth, CV_8UC3);
  std::vector<unsigned char> ppm;
  const std::string header = "P6\n48 32\n255\n";
  ppm.assign(header.begin(), header.end());
  std::vector<unsigned char> grey;
  std::vector<unsigned char> yuyv;
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      int rgb[3];
      truth_rgb(x, y, rgb);
      for (int c = 0; c < 3; ++c) {
        ppm.push_back(static_cast<unsigned char>(rgb[c]));
        bgr.at<cv::Vec3b>(y, x)[2 - c] = static_cast<unsigned char>(rgb[c]);
      }
    }
    // GREY: the red channel as the grey level (any known 8-bit image would do), rows padded.
    for (int x = 0; x < kWidth; ++x) {
      int rgb[3];
      truth_rgb(x, y, rgb);
      grey.push_back(static_cast<unsigned char>(rgb[0]));
    }
    for (int pad = 0; pad < 8; ++pad) {
      grey.push_back(0xAA);
    }
    // YUYV: Y0 Cb Y1 Cr per pair; ITU-R BT.601, studio range.
    for (int x = 0; x < kWidth; x += 2) {
      double cb = 0.0;
      double cr = 0.0;
      double luma[2];
      for (int k = 0; k < 2; ++k) {
        int rgb[3];
        truth_rgb(x + k, y, rgb);
        const double r = rgb[0] / 255.0;
        const double g = rgb[1] / 255.0;
        const double b = rgb[2] / 255.0;
        luma[k] = 16.0 + 65.481 * r + 128.553 * g + 24.966 * b;
        cb += 0.5 * (128.0 - 37.797 * r - 74.203 * g + 112.0 * b);
        cr += 0.5 * (128.0 + 112.0 * r - 93.786 * g - 18.214 * b);
      }
      yuyv.push_back(byte(luma[0]));
      yuyv.push_back(byte(cb));
      yuyv.push_back(byte(luma[1]));
      yuyv.push_back(byte(cr));
    }
  }
  write("truth.ppm", ppm);
  write("grey_48x32_bpl56.raw", grey);
  write("yuyv_48x32.raw", yuyv);
  std::vector<unsigned char> jpeg;
  cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 95});
  write("mjpeg_48x32.jpg", jpeg);
  // Drop every DHT segment (marker FF C4 + 2-byte length) before the scan.
  std::vector<unsigned char> stripped;
  std::size_t i = 0;
  while (i + 3 < jpeg.size()) {
    if (jpeg[i] == 0xFF && jpeg[i + 1] == 0xDA) {
      break;  // start of scan: the rest is entropy-coded data
    }
    if (jpeg[i] == 0xFF && jpeg[i + 1] == 0xC4) {
      i += 2 + ((static_cast<std::size_t>(jpeg[i + 2]) << 8) | jpeg[i + 3]);
      continue;
    }
    if (jpeg[i] == 0xFF && jpeg[i + 1] != 0xD8 && jpeg[i + 1] != 0x00) {
      const std::size_t length = 2 + ((static_cast<std::size_t>(jpeg[i + 2]) << 8) | jpeg[i + 3]);
      stripped.insert(stripped.end(), jpeg.begin() + static_cast<long>(i),
                      jpeg.begin() + static_cast<long>(i + length));
      i += length;
      continue;
    }
    stripped.push_back(jpeg[i]);
    ++i;
  }
  stripped.insert(stripped.end(), jpeg.begin() + static_cast<long>(i), jpeg.end());
  write("mjpeg_48x32_nodht.jpg", stripped);
  return 0;
}
