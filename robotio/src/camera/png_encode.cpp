#include "robocal/robotio/png_encode.hpp"

#include <png.h>
#include <zlib.h>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <csetjmp>
#include <stdexcept>
#include <vector>

namespace robocal::robotio {

namespace {

void append_bytes(png_structp png, png_bytep data, png_size_t length) {
  auto* out = static_cast<std::string*>(png_get_io_ptr(png));
  out->append(reinterpret_cast<const char*>(data), length);
}

void no_flush(png_structp /*png*/) {}

// libpng reports errors through longjmp; its message is kept for the exception thrown after.
void on_png_error(png_structp png, png_const_charp message) {
  auto* text = static_cast<std::string*>(png_get_error_ptr(png));
  if (text != nullptr) *text = message;
  png_longjmp(png, 1);
}

void on_png_warning(png_structp /*png*/, png_const_charp /*message*/) {}

int png_colour_type(int channels) {
  switch (channels) {
    case 1:
      return PNG_COLOR_TYPE_GRAY;
    case 3:
      return PNG_COLOR_TYPE_RGB;
    case 4:
      return PNG_COLOR_TYPE_RGB_ALPHA;
    default:
      return -1;
  }
}

std::string encode_with_opencv(const cv::Mat& image, int level, const std::string& what_for) {
  std::vector<unsigned char> encoded;
  if (!cv::imencode(".png", image, encoded,
                    {cv::IMWRITE_PNG_COMPRESSION, level, cv::IMWRITE_PNG_STRATEGY,
                     cv::IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY}))
    throw std::runtime_error(what_for + ": cannot encode the image");
  return {encoded.begin(), encoded.end()};
}

// The libpng calls, apart so that no object with a destructor lives in the frame setjmp marks.
bool encode_rows(png_structp png, png_infop info, const cv::Mat& image, int level, int bit_depth,
                 int colour_type) {
  if (setjmp(png_jmpbuf(png)) != 0) return false;  // NOLINT(cert-err52-cpp): libpng's protocol
  png_set_IHDR(png, info, static_cast<png_uint_32>(image.cols),
               static_cast<png_uint_32>(image.rows), bit_depth, colour_type, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_NONE);
  png_set_compression_level(png, level);
  png_set_compression_strategy(png, Z_HUFFMAN_ONLY);
  png_write_info(png, info);
  if (image.channels() >= 3) png_set_bgr(png);  // OpenCV's channel order
  if (bit_depth == 16) png_set_swap(png);       // PNG is big-endian; cv::Mat holds host order
  for (int r = 0; r < image.rows; ++r)
    png_write_row(png, const_cast<png_bytep>(image.ptr<png_byte>(r)));  // libpng's API: not written
  png_write_end(png, info);
  return true;
}

}  // namespace

std::string encode_png(const cv::Mat& image, int level, const std::string& what_for) {
  if (image.empty()) throw std::runtime_error(what_for + ": no image to encode (empty frame)");
  const int depth = image.depth();
  const int colour_type = png_colour_type(image.channels());
  if ((depth != CV_8U && depth != CV_16U) || colour_type < 0)
    return encode_with_opencv(image, level, what_for);
  std::string error;
  png_structp png =
      png_create_write_struct(PNG_LIBPNG_VER_STRING, &error, on_png_error, on_png_warning);
  if (png == nullptr) throw std::runtime_error(what_for + ": cannot start the PNG encoder");
  png_infop info = png_create_info_struct(png);
  std::string out;
  out.reserve(image.total() * image.elemSize() + 1024);
  png_set_write_fn(png, &out, append_bytes, no_flush);
  const bool ok = info != nullptr && encode_rows(png, info, image, std::clamp(level, 0, 9),
                                                 depth == CV_16U ? 16 : 8, colour_type);
  png_destroy_write_struct(&png, &info);
  if (!ok)
    throw std::runtime_error(what_for + ": cannot encode the image" +
                             (error.empty() ? std::string() : " (" + error + ")"));
  return out;
}

}  // namespace robocal::robotio
