#include "robocal/vision/target.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <opencv2/aruco/charuco.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <set>
#include <stdexcept>

namespace robocal::vision {

namespace {

// AprilTag families we can draw, with RAII around the C API.
struct FamilyDeleter {
  void (*destroy)(apriltag_family_t*);
  void operator()(apriltag_family_t* f) const { destroy(f); }
};
using FamilyPtr = std::unique_ptr<apriltag_family_t, FamilyDeleter>;

FamilyPtr make_family(const std::string& name) {
  if (name == "tag36h11") return FamilyPtr(tag36h11_create(), {tag36h11_destroy});
  if (name == "tag25h9") return FamilyPtr(tag25h9_create(), {tag25h9_destroy});
  if (name == "tag16h5") return FamilyPtr(tag16h5_create(), {tag16h5_destroy});
  return FamilyPtr(nullptr, {nullptr});
}

std::optional<cv::aruco::PREDEFINED_DICTIONARY_NAME> dictionary_from_name(const std::string& n) {
  using D = cv::aruco::PREDEFINED_DICTIONARY_NAME;
  static const std::pair<const char*, D> kNames[] = {
      {"DICT_4X4_50", cv::aruco::DICT_4X4_50},
      {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
      {"DICT_4X4_250", cv::aruco::DICT_4X4_250},
      {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
      {"DICT_5X5_50", cv::aruco::DICT_5X5_50},
      {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
      {"DICT_5X5_250", cv::aruco::DICT_5X5_250},
      {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
      {"DICT_6X6_50", cv::aruco::DICT_6X6_50},
      {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
      {"DICT_6X6_250", cv::aruco::DICT_6X6_250},
      {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
      {"DICT_7X7_50", cv::aruco::DICT_7X7_50},
      {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
      {"DICT_7X7_250", cv::aruco::DICT_7X7_250},
      {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
      {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL},
      {"DICT_APRILTAG_16h5", cv::aruco::DICT_APRILTAG_16h5},
      {"DICT_APRILTAG_25h9", cv::aruco::DICT_APRILTAG_25h9},
      {"DICT_APRILTAG_36h10", cv::aruco::DICT_APRILTAG_36h10},
      {"DICT_APRILTAG_36h11", cv::aruco::DICT_APRILTAG_36h11},
  };
  for (const auto& [name, value] : kNames)
    if (n == name) return value;
  return std::nullopt;
}

double default_tag_spacing(const TargetSpec& s) {
  return 0.3 * s.tag_size;
}

// Grid-order ids of an AprilTag grid (index r * cols + c).
std::vector<int> grid_ids(const TargetSpec& s) {
  if (!s.ids.empty()) return s.ids;
  std::vector<int> ids(static_cast<size_t>(s.cols * s.rows));
  for (int r = 0; r < s.rows; ++r)
    for (int c = 0; c < s.cols; ++c)
      ids[static_cast<size_t>(r * s.cols + c)] =
          s.first_id + (s.column_major ? c * s.rows + r : r * s.cols + c);
  return ids;
}

std::string fail(std::string* field, const char* key, const std::string& what) {
  if (field) *field = key;
  return what;
}

void add_chess_corners(TargetBoard* board, int cols, int rows, double s) {
  for (int j = 0; j < rows - 1; ++j)
    for (int i = 0; i < cols - 1; ++i)
      board->corners.push_back({j * (cols - 1) + i, Eigen::Vector3d((i + 1) * s, (j + 1) * s, 0)});
}

void build_apriltag_grid(TargetBoard* board) {
  const TargetSpec& s = board->spec;
  const FamilyPtr family = make_family(s.family);
  const int wab = family->width_at_border;
  const int total = family->total_width;
  const double module = s.tag_size / wab;
  const double pitch = s.tag_size + s.tag_spacing;
  const int border_start = (total - wab) / 2;
  const std::vector<int> ids = grid_ids(s);
  for (int r = 0; r < s.rows; ++r) {
    for (int c = 0; c < s.cols; ++c) {
      const int id = ids[static_cast<size_t>(r * s.cols + c)];
      const double x = c * pitch, y = r * pitch;
      image_u8_t* im = apriltag_to_image(family.get(), id);
      PatternPatch patch;
      patch.x0 = x - border_start * module;
      patch.y0 = y - border_start * module;
      patch.module = module;
      patch.nx = im->width;
      patch.ny = im->height;
      patch.black.resize(static_cast<size_t>(patch.nx * patch.ny));
      for (int v = 0; v < im->height; ++v)
        for (int u = 0; u < im->width; ++u)
          patch.black[static_cast<size_t>(v * patch.nx + u)] = im->buf[v * im->stride + u] == 0;
      // libapriltag 3.3 does not export image_u8_destroy; it is exactly these two frees.
      std::free(im->buf);
      std::free(im);
      board->patches.push_back(std::move(patch));

      TargetMarker marker;
      marker.id = id;
      const double sz = s.tag_size;
      marker.corners[0] = Eigen::Vector3d(x, y + sz, 0);
      marker.corners[1] = Eigen::Vector3d(x + sz, y + sz, 0);
      marker.corners[2] = Eigen::Vector3d(x + sz, y, 0);
      marker.corners[3] = Eigen::Vector3d(x, y, 0);
      for (int k = 0; k < 4; ++k) board->corners.push_back({id * 4 + k, marker.corners[k]});
      board->markers.push_back(marker);
    }
  }
  const double w = s.cols * s.tag_size + (s.cols - 1) * s.tag_spacing;
  const double h = s.rows * s.tag_size + (s.rows - 1) * s.tag_spacing;
  board->extent_min = Eigen::Vector2d(-s.margin, -s.margin);
  board->extent_max = Eigen::Vector2d(w + s.margin, h + s.margin);
}

void build_chessboard(TargetBoard* board) {
  const TargetSpec& s = board->spec;
  PatternPatch patch;
  patch.module = s.square_size;
  patch.nx = s.cols;
  patch.ny = s.rows;
  patch.black.resize(static_cast<size_t>(s.cols * s.rows));
  for (int j = 0; j < s.rows; ++j)
    for (int i = 0; i < s.cols; ++i)
      patch.black[static_cast<size_t>(j * s.cols + i)] = (i + j) % 2 == 0;
  board->patches.push_back(std::move(patch));
  add_chess_corners(board, s.cols, s.rows, s.square_size);
  board->extent_min = Eigen::Vector2d(-s.margin, -s.margin);
  board->extent_max =
      Eigen::Vector2d(s.cols * s.square_size + s.margin, s.rows * s.square_size + s.margin);
}

// The layout is taken from OpenCV's own CharucoBoard so it is exactly what this OpenCV version
// detects; coordinates are recomputed in double (OpenCV stores floats) and cross-checked.
void build_charuco(TargetBoard* board) {
  const TargetSpec& s = board->spec;
  const auto dict = cv::aruco::getPredefinedDictionary(*dictionary_from_name(s.dictionary));
  const auto cvb = cv::aruco::CharucoBoard::create(
      s.cols, s.rows, static_cast<float>(s.square_size), static_cast<float>(s.marker_size), dict);
  const double sq = s.square_size, m = s.marker_size;
  const double tol = 1e-5 * sq + 1e-6;  // float storage in OpenCV
  std::vector<std::uint8_t> has_marker(static_cast<size_t>(s.cols * s.rows), 0);
  std::vector<PatternPatch> marker_patches;
  const int n = dict->markerSize;
  for (size_t k = 0; k < cvb->ids.size(); ++k) {
    const auto& op = cvb->objPoints[k];
    const double cx = 0.25 * (op[0].x + op[1].x + op[2].x + op[3].x);
    const double cy = 0.25 * (op[0].y + op[1].y + op[2].y + op[3].y);
    const int i = static_cast<int>(std::floor(cx / sq));
    const int j = static_cast<int>(std::floor(cy / sq));
    has_marker[static_cast<size_t>(j * s.cols + i)] = 1;
    TargetMarker marker;
    marker.id = cvb->ids[k];
    const double x0 = i * sq + 0.5 * (sq - m), y0 = j * sq + 0.5 * (sq - m);
    // ArUco corner order: top-left, top-right, bottom-right, bottom-left (clockwise on screen).
    marker.corners[0] = Eigen::Vector3d(x0, y0, 0);
    marker.corners[1] = Eigen::Vector3d(x0 + m, y0, 0);
    marker.corners[2] = Eigen::Vector3d(x0 + m, y0 + m, 0);
    marker.corners[3] = Eigen::Vector3d(x0, y0 + m, 0);
    for (int c = 0; c < 4; ++c) {
      if (std::abs(marker.corners[c].x() - op[static_cast<size_t>(c)].x) > tol ||
          std::abs(marker.corners[c].y() - op[static_cast<size_t>(c)].y) > tol)
        throw std::logic_error("ChArUco layout differs from OpenCV's board object");
    }
    board->markers.push_back(marker);

    cv::Mat img;
    dict->drawMarker(marker.id, n + 2, img, 1);
    PatternPatch patch;
    patch.x0 = x0;
    patch.y0 = y0;
    patch.module = m / (n + 2);
    patch.nx = patch.ny = n + 2;
    patch.black.resize(static_cast<size_t>((n + 2) * (n + 2)));
    for (int v = 0; v < n + 2; ++v)
      for (int u = 0; u < n + 2; ++u)
        patch.black[static_cast<size_t>(v * (n + 2) + u)] = img.at<std::uint8_t>(v, u) < 128;
    marker_patches.push_back(std::move(patch));
  }
  PatternPatch squares;
  squares.module = sq;
  squares.nx = s.cols;
  squares.ny = s.rows;
  squares.black.resize(has_marker.size());
  for (size_t k = 0; k < has_marker.size(); ++k) squares.black[k] = has_marker[k] ? 0 : 1;
  board->patches.push_back(std::move(squares));
  for (PatternPatch& p : marker_patches) board->patches.push_back(std::move(p));

  add_chess_corners(board, s.cols, s.rows, sq);
  if (cvb->chessboardCorners.size() != board->corners.size())
    throw std::logic_error("ChArUco corner count differs from OpenCV's board object");
  for (size_t k = 0; k < board->corners.size(); ++k) {
    const auto& p = cvb->chessboardCorners[k];
    if (std::abs(board->corners[k].point.x() - p.x) > tol ||
        std::abs(board->corners[k].point.y() - p.y) > tol)
      throw std::logic_error("ChArUco corner order differs from OpenCV's board object");
  }
  board->extent_min = Eigen::Vector2d(-s.margin, -s.margin);
  board->extent_max = Eigen::Vector2d(s.cols * sq + s.margin, s.rows * sq + s.margin);
}

}  // namespace

std::string target_kind_name(TargetKind kind) {
  switch (kind) {
    case TargetKind::kChessboard:
      return "chessboard";
    case TargetKind::kCharuco:
      return "charuco";
    case TargetKind::kAprilTagGrid:
    default:
      return "apriltag_grid";
  }
}

std::string check_target_spec(const TargetSpec& s, std::string* field) {
  const bool apriltag = s.kind == TargetKind::kAprilTagGrid;
  const int min_n = apriltag ? 1 : 2;
  if (s.cols < min_n)
    return fail(
        field, "cols",
        "cols must be at least " + std::to_string(min_n) + " (got " + std::to_string(s.cols) + ")");
  if (s.rows < min_n)
    return fail(
        field, "rows",
        "rows must be at least " + std::to_string(min_n) + " (got " + std::to_string(s.rows) + ")");
  if (s.cols > 1000 || s.rows > 1000) return fail(field, "cols", "cols and rows must be <= 1000");
  if (apriltag) {
    const FamilyPtr family = make_family(s.family);
    if (!family)
      return fail(
          field, "family",
          "unknown AprilTag family '" + s.family + "' (expected tag36h11, tag25h9 or tag16h5)");
    if (!(s.tag_size > 0.0) || !std::isfinite(s.tag_size))
      return fail(field, "tag_size", "tag_size must be a positive length in metres");
    const double module = s.tag_size / family->width_at_border;
    const double spacing = s.tag_spacing < 0 ? default_tag_spacing(s) : s.tag_spacing;
    if (!(spacing >= 2.0 * module * (1.0 - 1e-9)) || !std::isfinite(spacing))
      return fail(field, "tag_spacing",
                  "tag_spacing must be at least 2 tag modules (" + std::to_string(2.0 * module) +
                      " m) so every tag keeps its own white quiet zone");
    if (s.margin >= 0 && s.margin < module * (1.0 - 1e-9))
      return fail(field, "margin",
                  "margin must be at least one tag module (" + std::to_string(module) + " m)");
    if (!s.ids.empty() && s.ids.size() != static_cast<size_t>(s.cols * s.rows))
      return fail(field, "ids",
                  "ids must list cols*rows = " + std::to_string(s.cols * s.rows) +
                      " tag ids (got " + std::to_string(s.ids.size()) + ")");
    std::set<int> seen;
    for (int id : grid_ids(s)) {
      if (id < 0 || id >= static_cast<int>(family->ncodes))
        return fail(field, s.ids.empty() ? "first_id" : "ids",
                    "tag id " + std::to_string(id) + " is outside " + s.family + " (0.." +
                        std::to_string(family->ncodes - 1) + ")");
      if (!seen.insert(id).second)
        return fail(field, "ids", "tag id " + std::to_string(id) + " appears twice");
    }
    return {};
  }
  if (!(s.square_size > 0.0) || !std::isfinite(s.square_size))
    return fail(field, "square_size", "square_size must be a positive length in metres");
  if (s.kind == TargetKind::kCharuco) {
    const auto dict_name = dictionary_from_name(s.dictionary);
    if (!dict_name)
      return fail(field, "dictionary",
                  "unknown ArUco dictionary '" + s.dictionary +
                      "' (expected an OpenCV name such as DICT_6X6_250)");
    if (!(s.marker_size > 0.0) || !(s.marker_size < s.square_size))
      return fail(field, "marker_size",
                  "marker_size must be positive and smaller than square_size");
    const auto dict = cv::aruco::getPredefinedDictionary(*dict_name);
    const int markers = (s.cols * s.rows) / 2;
    if (markers > dict->bytesList.rows)
      return fail(field, "cols",
                  "the board needs " + std::to_string(markers) + " markers but " + s.dictionary +
                      " has " + std::to_string(dict->bytesList.rows));
  }
  if (s.margin >= 0 && !std::isfinite(s.margin))
    return fail(field, "margin", "margin must be a finite length");
  return {};
}

TargetBoard build_target(const TargetSpec& spec) {
  const std::string problem = check_target_spec(spec);
  if (!problem.empty()) throw std::invalid_argument(problem);
  TargetBoard board;
  board.spec = spec;
  TargetSpec& s = board.spec;
  switch (s.kind) {
    case TargetKind::kAprilTagGrid:
      if (s.tag_spacing < 0) s.tag_spacing = default_tag_spacing(s);
      if (s.margin < 0) s.margin = s.tag_spacing;
      build_apriltag_grid(&board);
      break;
    case TargetKind::kChessboard:
      if (s.margin < 0) s.margin = s.square_size;
      build_chessboard(&board);
      break;
    case TargetKind::kCharuco:
      if (s.margin < 0) s.margin = 0.5 * s.square_size;
      build_charuco(&board);
      break;
  }
  std::sort(board.corners.begin(), board.corners.end(),
            [](const TargetCorner& a, const TargetCorner& b) { return a.id < b.id; });
  return board;
}

std::optional<Eigen::Vector3d> corner_point(const TargetBoard& board, int id) {
  const auto it = std::lower_bound(board.corners.begin(), board.corners.end(), id,
                                   [](const TargetCorner& c, int v) { return c.id < v; });
  if (it == board.corners.end() || it->id != id) return std::nullopt;
  return it->point;
}

bool is_black(const TargetBoard& board, double x, double y) {
  for (const PatternPatch& p : board.patches) {
    const double u = (x - p.x0) / p.module, v = (y - p.y0) / p.module;
    if (u < 0 || v < 0 || u >= p.nx || v >= p.ny) continue;
    if (p.black[static_cast<size_t>(static_cast<int>(v) * p.nx + static_cast<int>(u))]) return true;
  }
  return false;
}

bool on_board(const TargetBoard& board, double x, double y) {
  return x >= board.extent_min.x() && y >= board.extent_min.y() && x <= board.extent_max.x() &&
         y <= board.extent_max.y();
}

}  // namespace robocal::vision
