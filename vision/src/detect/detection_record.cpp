#include "robocal/vision/detection_record.hpp"

#include "robocal/vision/target_io.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>

namespace robocal::vision {

namespace {

constexpr const char* kFormat = "robocal detection record 1";

// detection_status_name's inverse.
DetectionStatus status_of(const std::string& name) {
  if (name == "found") return DetectionStatus::kFound;
  if (name == "partial") return DetectionStatus::kPartial;
  if (name == "rejected") return DetectionStatus::kRejected;
  throw std::invalid_argument("unknown detection status '" + name + "'");
}

// NaN has no JSON number: null.
nlohmann::json number(double x) {
  return std::isnan(x) ? nlohmann::json(nullptr) : nlohmann::json(x);
}

double number_of(const nlohmann::json& j) {
  return j.is_null() ? std::numeric_limits<double>::quiet_NaN() : j.get<double>();
}

nlohmann::json to_json(const TargetDetection& d) {
  nlohmann::json points = nlohmann::json::array(), pixels = nlohmann::json::array();
  for (const Eigen::Vector3d& p : d.board_points) points.push_back({p.x(), p.y(), p.z()});
  for (const Eigen::Vector2d& p : d.pixels) pixels.push_back({p.x(), p.y()});
  nlohmann::json groups = nlohmann::json::array();
  for (const CornerGroup& g : d.corner_groups) {
    const std::vector<double> cov(g.covariance.data(), g.covariance.data() + g.covariance.size());
    groups.push_back({{"corner_ids", g.corner_ids},
                      {"rows", g.covariance.rows()},
                      {"cols", g.covariance.cols()},
                      {"covariance", cov}});
  }
  return {{"status", detection_status_name(d.status)},
          {"reason", d.reason},
          {"missing_marker_ids", d.missing_marker_ids},
          {"corner_ids", d.corner_ids},
          {"board_points", points},
          {"pixels", pixels},
          {"edge_blur_px", number(d.edge_blur_px)},
          {"corner_groups", groups}};
}

TargetDetection detection_of(const nlohmann::json& j) {
  TargetDetection d;
  d.status = status_of(j.at("status").get<std::string>());
  d.reason = j.at("reason").get<std::string>();
  d.missing_marker_ids = j.at("missing_marker_ids").get<std::vector<int>>();
  d.corner_ids = j.at("corner_ids").get<std::vector<int>>();
  for (const auto& p : j.at("board_points"))
    d.board_points.emplace_back(p.at(0).get<double>(), p.at(1).get<double>(),
                                p.at(2).get<double>());
  for (const auto& p : j.at("pixels"))
    d.pixels.emplace_back(p.at(0).get<double>(), p.at(1).get<double>());
  if (d.pixels.size() != d.corner_ids.size() || d.board_points.size() != d.corner_ids.size())
    throw std::invalid_argument("corner lists of different lengths");
  d.edge_blur_px = number_of(j.at("edge_blur_px"));
  for (const auto& g : j.at("corner_groups")) {
    CornerGroup group;
    group.corner_ids = g.at("corner_ids").get<std::vector<int>>();
    const auto rows = g.at("rows").get<Eigen::Index>(), cols = g.at("cols").get<Eigen::Index>();
    const auto cov = g.at("covariance").get<std::vector<double>>();
    if (rows < 0 || cols < 0 || static_cast<std::size_t>(rows * cols) != cov.size())
      throw std::invalid_argument("a corner covariance of the wrong size");
    group.covariance = Eigen::Map<const Eigen::MatrixXd>(cov.data(), rows, cols);
    d.corner_groups.push_back(std::move(group));
  }
  return d;
}

}  // namespace

std::string detection_signature(const TargetBoard& board, const AprilTagDetectorOptions& o) {
  return fmt::format(
      "family={} decimate={} threads={} sigma={} refine_edges={} sharpening={} hamming={} "
      "subpixel={} margin={} board={:016x}",
      o.family, o.quad_decimate, o.threads, o.quad_sigma, o.refine_edges, o.decode_sharpening,
      o.max_hamming, o.subpixel_refine, o.min_decision_margin,
      content_hash(target_to_yaml(board.spec)));
}

std::uint64_t content_hash(std::string_view bytes) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (const char c : bytes) {
    h ^= static_cast<unsigned char>(c);
    h *= 0x100000001b3ULL;
  }
  return h;
}

std::string detection_record_to_json(const std::string& signature, const DetectionRecord& record) {
  nlohmann::json images = nlohmann::json::object();
  for (const auto& [file, entry] : record)
    images[file] = {{"size", entry.size},
                    {"fnv1a64", fmt::format("{:016x}", entry.hash)},
                    {"width", entry.width},
                    {"height", entry.height},
                    {"detection", to_json(entry.detection)}};
  const nlohmann::json j = {{"format", kFormat}, {"detector", signature}, {"images", images}};
  return j.dump() + "\n";
}

DetectionRecord read_detection_record(const std::filesystem::path& file,
                                      const std::string& signature) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return {};
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  const auto field_is = [&j](const char* key, const std::string& expected) {
    const auto it = j.find(key);
    return it != j.end() && it->is_string() && it->get_ref<const std::string&>() == expected;
  };
  if (j.is_discarded() || !j.is_object() || !field_is("format", kFormat) ||
      !field_is("detector", signature))
    return {};
  DetectionRecord record;
  try {
    for (const auto& [name, e] : j.at("images").items()) {
      RecordedDetection entry;
      entry.size = e.at("size").get<std::uintmax_t>();
      entry.hash = std::stoull(e.at("fnv1a64").get<std::string>(), nullptr, 16);
      entry.width = e.at("width").get<int>();
      entry.height = e.at("height").get<int>();
      entry.detection = detection_of(e.at("detection"));
      record[name] = std::move(entry);
    }
  } catch (const std::exception&) {
    return {};  // damaged: detect the images instead
  }
  return record;
}

const RecordedDetection* matching_entry(const DetectionRecord& record,
                                        const std::filesystem::path& image,
                                        std::string_view bytes) {
  const auto it = record.find(image.filename().string());
  if (it == record.end() || it->second.size != bytes.size() ||
      it->second.hash != content_hash(bytes))
    return nullptr;
  return &it->second;
}

}  // namespace robocal::vision
