#include "robocal/vision/target_io.hpp"

#include "models/yaml_util.hpp"

#include <cstdio>
#include <sstream>
#include <stdexcept>

namespace robocal::vision {

TargetBoard parse_target_yaml(const std::string& text, const std::string& source) {
  const detail::YamlContext ctx{source};
  const YAML::Node root = detail::load_yaml_text(text, source);
  if (!root || !root.IsMap()) ctx.fail("a target file must be a YAML mapping (type, cols, ...)");
  TargetSpec spec;
  const YAML::Node type = ctx.require(root, "type");
  const std::string type_name = ctx.to_string(type, "type");
  if (type_name == "apriltag_grid") {
    spec.kind = TargetKind::kAprilTagGrid;
    ctx.reject_unknown_keys(root, {"type", "name", "cols", "rows", "margin", "family", "tag_size",
                                   "tag_spacing", "first_id", "id_order", "ids"});
  } else if (type_name == "chessboard") {
    spec.kind = TargetKind::kChessboard;
    ctx.reject_unknown_keys(root, {"type", "name", "cols", "rows", "margin", "square_size"});
  } else if (type_name == "charuco") {
    spec.kind = TargetKind::kCharuco;
    ctx.reject_unknown_keys(root, {"type", "name", "cols", "rows", "margin", "square_size",
                                   "marker_size", "dictionary"});
  } else {
    ctx.fail(type, "unknown target type '" + type_name +
                       "' (expected apriltag_grid, chessboard or charuco)");
  }
  if (const YAML::Node n = root["name"]) spec.name = ctx.to_string(n, "name");
  spec.cols = ctx.to_int(ctx.require(root, "cols"), "cols");
  spec.rows = ctx.to_int(ctx.require(root, "rows"), "rows");
  if (const YAML::Node n = root["margin"]) {
    spec.margin = ctx.to_double(n, "margin");
    if (spec.margin < 0) ctx.fail(n, "margin must not be negative");
  }
  if (spec.kind == TargetKind::kAprilTagGrid) {
    if (const YAML::Node n = root["family"]) spec.family = ctx.to_string(n, "family");
    spec.tag_size = ctx.to_double(ctx.require(root, "tag_size"), "tag_size");
    if (const YAML::Node n = root["tag_spacing"]) {
      spec.tag_spacing = ctx.to_double(n, "tag_spacing");
      if (spec.tag_spacing < 0) ctx.fail(n, "tag_spacing must not be negative");
    }
    if (const YAML::Node n = root["first_id"]) spec.first_id = ctx.to_int(n, "first_id");
    if (const YAML::Node n = root["id_order"]) {
      const std::string order = ctx.to_string(n, "id_order");
      if (order == "column_major") {
        spec.column_major = true;
      } else if (order != "row_major") {
        ctx.fail(n, "id_order must be row_major or column_major (got '" + order + "')");
      }
    }
    if (const YAML::Node n = root["ids"]) {
      if (!n.IsSequence()) ctx.fail(n, "'ids' must be a list of integers");
      for (const YAML::Node& item : n) spec.ids.push_back(ctx.to_int(item, "ids"));
    }
  } else {
    spec.square_size = ctx.to_double(ctx.require(root, "square_size"), "square_size");
    if (spec.kind == TargetKind::kCharuco) {
      spec.marker_size = ctx.to_double(ctx.require(root, "marker_size"), "marker_size");
      if (const YAML::Node n = root["dictionary"]) spec.dictionary = ctx.to_string(n, "dictionary");
    }
  }
  std::string field;
  const std::string problem = check_target_spec(spec, &field);
  if (!problem.empty()) {
    const YAML::Node n = root[field];
    if (n) ctx.fail(n, problem);
    ctx.fail(root, problem);
  }
  return build_target(spec);
}

TargetBoard load_target_file(const std::filesystem::path& path) {
  return parse_target_yaml(detail::read_text_file(path), path.string());
}

std::string target_to_yaml(const TargetSpec& s) {
  std::ostringstream out;
  out.precision(17);
  out << "type: " << target_kind_name(s.kind) << "\n";
  if (!s.name.empty()) out << "name: \"" << s.name << "\"\n";
  out << "cols: " << s.cols << "\nrows: " << s.rows << "\n";
  if (s.kind == TargetKind::kAprilTagGrid) {
    out << "family: " << s.family << "\ntag_size: " << s.tag_size << "\n";
    if (s.tag_spacing >= 0) out << "tag_spacing: " << s.tag_spacing << "\n";
    if (!s.ids.empty()) {
      out << "ids: [";
      for (size_t i = 0; i < s.ids.size(); ++i) out << (i ? ", " : "") << s.ids[i];
      out << "]\n";
    } else {
      out << "first_id: " << s.first_id
          << "\nid_order: " << (s.column_major ? "column_major" : "row_major") << "\n";
    }
  } else {
    out << "square_size: " << s.square_size << "\n";
    if (s.kind == TargetKind::kCharuco)
      out << "marker_size: " << s.marker_size << "\ndictionary: " << s.dictionary << "\n";
  }
  if (s.margin >= 0) out << "margin: " << s.margin << "\n";
  return out.str();
}

namespace {

// Calls emit(patch, u, v, end) for every horizontal run of black modules u..end-1 in row v of
// every patch: one rectangle per run keeps the SVG and PDF files small.
template <typename Emit>
void for_each_black_run(const TargetBoard& board, Emit&& emit) {
  for (const PatternPatch& p : board.patches) {
    for (int v = 0; v < p.ny; ++v) {
      for (int u = 0; u < p.nx;) {
        if (!p.black[static_cast<size_t>(v * p.nx + u)]) {
          ++u;
          continue;
        }
        int end = u;
        while (end < p.nx && p.black[static_cast<size_t>(v * p.nx + end)]) ++end;
        emit(p, u, v, end);
        u = end;
      }
    }
  }
}

}  // namespace

std::string target_to_svg(const TargetBoard& board) {
  const double mm = 1000.0;
  const Eigen::Vector2d size = board.extent_max - board.extent_min;
  std::ostringstream out;
  out.precision(10);
  out << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  out << "<!-- robocal target: print at 100 % (actual size, no fit-to-page).\n"
      << target_to_yaml(board.spec) << "paper: " << size.x() * mm << " mm x " << size.y() * mm
      << " mm -->\n";
  out << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << size.x() * mm << "mm\" height=\""
      << size.y() * mm << "mm\" viewBox=\"0 0 " << size.x() * mm << " " << size.y() * mm
      << "\" shape-rendering=\"crispEdges\">\n";
  out << "<rect x=\"0\" y=\"0\" width=\"" << size.x() * mm << "\" height=\"" << size.y() * mm
      << "\" fill=\"#ffffff\"/>\n<g fill=\"#000000\">\n";
  for_each_black_run(board, [&](const PatternPatch& p, int u, int v, int end) {
    const double x = (p.x0 + u * p.module - board.extent_min.x()) * mm;
    const double y = (p.y0 + v * p.module - board.extent_min.y()) * mm;
    out << "<rect x=\"" << x << "\" y=\"" << y << "\" width=\"" << (end - u) * p.module * mm
        << "\" height=\"" << p.module * mm << "\"/>\n";
  });
  out << "</g>\n</svg>\n";
  return out.str();
}

void save_target_svg(const TargetBoard& board, const std::filesystem::path& path) {
  detail::write_text_file_atomic(path, target_to_svg(board));
}

std::string target_to_pdf(const TargetBoard& board) {
  const double pt = 72.0 / 0.0254;  // points per metre
  const Eigen::Vector2d size = board.extent_max - board.extent_min;
  std::ostringstream content;
  content.setf(std::ios::fixed);
  content.precision(4);
  content << "0 g\n";
  for_each_black_run(board, [&](const PatternPatch& p, int u, int v, int end) {
    // PDF's origin is the bottom-left corner of the page, y up.
    const double x = (p.x0 + u * p.module - board.extent_min.x()) * pt;
    const double y = (board.extent_max.y() - (p.y0 + (v + 1) * p.module)) * pt;
    content << x << " " << y << " " << (end - u) * p.module * pt << " " << p.module * pt
            << " re f\n";
  });
  const std::string stream = content.str();
  std::ostringstream pdf;
  pdf.setf(std::ios::fixed);
  pdf.precision(4);
  std::vector<size_t> offsets;
  pdf << "%PDF-1.4\n";
  auto object = [&](const std::string& body) {
    offsets.push_back(static_cast<size_t>(pdf.tellp()));
    pdf << offsets.size() << " 0 obj\n" << body << "\nendobj\n";
  };
  object("<< /Type /Catalog /Pages 2 0 R >>");
  object("<< /Type /Pages /Kids [3 0 R] /Count 1 >>");
  std::ostringstream page;
  page.setf(std::ios::fixed);
  page.precision(4);
  page << "<< /Type /Page /Parent 2 0 R /MediaBox [0 0 " << size.x() * pt << " " << size.y() * pt
       << "] /Contents 4 0 R /Resources << >> >>";
  object(page.str());
  object("<< /Length " + std::to_string(stream.size()) + " >>\nstream\n" + stream + "endstream");
  const size_t xref = static_cast<size_t>(pdf.tellp());
  pdf << "xref\n0 " << offsets.size() + 1 << "\n0000000000 65535 f \n";
  for (size_t off : offsets) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%010zu 00000 n \n", off);
    pdf << buf;
  }
  pdf << "trailer\n<< /Size " << offsets.size() + 1 << " /Root 1 0 R >>\nstartxref\n"
      << xref << "\n%%EOF\n";
  return pdf.str();
}

void save_target_pdf(const TargetBoard& board, const std::filesystem::path& path) {
  detail::write_text_file_atomic(path, target_to_pdf(board));
}

}  // namespace robocal::vision
