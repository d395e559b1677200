#include "summary/report_page.hpp"

#include "summary/svg_plot.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <numeric>

namespace robocal::app {

namespace {

using svg::axes;
using svg::escape;
using svg::figure;
using svg::Frame;
using svg::legend;
using svg::length;
using svg::log_ticks;
using svg::scale_colour;
using svg::svg_open;
using svg::ticks;

constexpr const char* kBefore = "#8c8c8c";  // nominal model
constexpr const char* kAfter = "#1f6fb2";   // calibrated model

// ---- the figures --------------------------------------------------------------------------------

std::string accuracy_section(const ReportData& d) {
  std::string s =
      "<table class=\"num\"><tr><th>poses</th><th>how many</th><th>before: RMS</th>"
      "<th>before: worst</th><th>after: RMS</th><th>after: worst</th></tr>\n";
  for (const auto& a : d.accuracy)
    s += fmt::format(
        "<tr><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>"
        "<td>{}</td></tr>\n",
        escape(a.label), a.poses, a.nominal_rms ? length(*a.nominal_rms) : "—",
        a.nominal_max ? length(*a.nominal_max) : "—", length(a.calibrated_rms),
        length(a.calibrated_max));
  s += "</table>\n";
  // Bars on a log scale: before and after differ by orders of magnitude.
  double lo = 1e300, hi = 0;
  for (const auto& a : d.accuracy) {
    for (const auto& v : {a.nominal_rms, a.nominal_max, std::optional<double>(a.calibrated_rms),
                          std::optional<double>(a.calibrated_max)})
      if (v && *v > 0) {
        lo = std::min(lo, *v);
        hi = std::max(hi, *v);
      }
  }
  const int height = 60 + 46 * static_cast<int>(std::max<std::size_t>(d.accuracy.size(), 1));
  // The label column fits the longest row label ("held-out poses, measured by the cameras").
  std::string svg = svg_open("fig-accuracy", 700, height, "accuracy before and after");
  if (hi > 0) {
    Frame f;
    f.x0 = 250;
    f.w = 420;
    f.h = height - 60;
    f.log_y = false;
    const double llo = std::pow(10.0, std::floor(std::log10(lo))),
                 lhi = std::pow(10.0, std::ceil(std::log10(hi)));
    const auto bx = [&](double v) {
      return f.x0 + (std::log10(v) - std::log10(llo)) / (std::log10(lhi) - std::log10(llo)) * f.w;
    };
    svg += fmt::format(
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" "
        "stroke=\"#444\"/>\n",
        f.x0, f.y0, f.w, f.h);
    for (const double t : log_ticks(llo, lhi))
      svg += fmt::format(
          "<line x1=\"{0:.1f}\" y1=\"{1}\" x2=\"{0:.1f}\" y2=\"{2}\" stroke=\"#ddd\"/>"
          "<text x=\"{0:.1f}\" y=\"{3}\" class=\"tick\" text-anchor=\"middle\">{4}</text>\n",
          bx(t), f.y0, f.y0 + f.h, f.y0 + f.h + 14, escape(length(t)));
    double y = f.y0 + 6;
    for (const auto& a : d.accuracy) {
      svg +=
          fmt::format("<text x=\"{}\" y=\"{:.1f}\" class=\"tick\" text-anchor=\"end\">{}</text>\n",
                      f.x0 - 6, y + 20, escape(a.label));
      if (a.nominal_rms && *a.nominal_rms > 0)
        svg += fmt::format(
            "<rect x=\"{}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"15\" "
            "fill=\"{}\"><title>before: {}</title></rect>\n",
            f.x0, y, std::max(1.0, bx(*a.nominal_rms) - f.x0), kBefore,
            escape(length(*a.nominal_rms)));
      if (a.calibrated_rms > 0)
        svg += fmt::format(
            "<rect x=\"{}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"15\" "
            "fill=\"{}\"><title>after: {}</title></rect>\n",
            f.x0, y + 17, std::max(1.0, bx(a.calibrated_rms) - f.x0), kAfter,
            escape(length(a.calibrated_rms)));
      y += 46;
    }
    svg += fmt::format(
        "<text x=\"{:.1f}\" y=\"{}\" class=\"axis\" text-anchor=\"middle\">RMS "
        "position error (logarithmic scale)</text>\n",
        f.x0 + f.w / 2, height - 8);
  }
  svg += "</svg>";
  return s + figure(svg,
                    "RMS position error of the tool before calibration (grey: the robot's "
                    "drawing, placed by a best fit) and after (blue: the calibrated model). " +
                        escape(d.accuracy_note));
}

std::string per_pose_section(const ReportData& d) {
  std::string svg = svg_open("fig-per-pose", 640, 290, "error per pose before and after");
  const auto n = d.error_after.size();
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  // Sorted by the error before calibration (or after, without a before): the curve reads as
  // "how many poses are worse than this".
  const auto& key = d.error_before.size() == n ? d.error_before : d.error_after;
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return key[a] > key[b]; });
  double lo = 1e300, hi = 0;
  for (const auto* v : {&d.error_before, &d.error_after})
    for (const double e : *v)
      if (e > 0) {
        lo = std::min(lo, e);
        hi = std::max(hi, e);
      }
  if (n > 0 && hi > 0) {
    Frame f;
    f.log_y = true;
    f.xlo = 0;
    f.xhi = static_cast<double>(std::max<std::size_t>(n, 2) - 1);
    f.ylo = std::pow(10.0, std::floor(std::log10(lo)));
    f.yhi = std::pow(10.0, std::ceil(std::log10(hi)));
    const bool has_before = d.error_before.size() == n;
    svg += axes(
        f, svg::count_ticks(f.xhi, 8), log_ticks(f.ylo, f.yhi),
        has_before ? "poses, sorted by error before calibration"
                   : "poses, sorted by error after calibration",
        "position error", [](double t) { return fmt::format("{:.0f}", t); },
        [](double t) { return length(t); });
    for (const auto& [values, colour] :
         {std::pair{&d.error_before, kBefore}, std::pair{&d.error_after, kAfter}}) {
      if (values->size() != n) continue;
      std::string dots;
      for (std::size_t i = 0; i < n; ++i)
        dots += fmt::format("M{:.1f} {:.1f}h0", f.px(static_cast<double>(i)),
                            f.py(std::max((*values)[order[i]], f.ylo)));
      svg += fmt::format(
          "<path d=\"{}\" stroke=\"{}\" stroke-width=\"3\" stroke-linecap=\"round\" "
          "fill=\"none\"/>\n",
          dots, colour);
    }
    if (has_before)
      svg += legend(f.x0 + f.w - 130, f.y0 + 6,
                    {{kBefore, "before calibration"}, {kAfter, "after calibration"}});
  }
  svg += "</svg>";
  const std::string what =
      d.error_before.size() == n
          ? "before (grey) and after (blue) calibration, largest error before calibration on the "
            "left"
          : "after calibration, largest on the left";
  return figure(svg, fmt::format("Error of each of the {} {}, {}. The scale is logarithmic: each "
                                 "grid line is ten times the one below.",
                                 n, escape(d.per_pose_source), what));
}

std::string histogram_svg(const std::string& id, const calib::Histogram& h, const char* colour,
                          const std::string& title) {
  std::string svg = svg_open(id, 320, 240, title);
  if (!h.counts.empty()) {
    Frame f;
    f.x0 = 50;
    f.w = 255;
    f.h = 160;
    f.y0 = 24;
    f.xlo = h.lo;
    f.xhi = h.lo + h.width * static_cast<double>(h.counts.size());
    f.ylo = 0;
    f.yhi = static_cast<double>(
        std::max<std::size_t>(1, *std::max_element(h.counts.begin(), h.counts.end())));
    svg += axes(
        f, ticks(f.xlo, f.xhi, 4), svg::count_ticks(f.yhi, 4), "position error", "poses",
        [](double t) { return length(t); }, [](double t) { return fmt::format("{:.0f}", t); });
    for (std::size_t i = 0; i < h.counts.size(); ++i) {
      const double x = h.lo + h.width * static_cast<double>(i);
      svg += fmt::format(
          "<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" "
          "fill=\"{}\"><title>{} poses</title></rect>\n",
          f.px(x) + 0.5, f.py(static_cast<double>(h.counts[i])),
          std::max(0.5, f.px(x + h.width) - f.px(x) - 1.0),
          f.py(0) - f.py(static_cast<double>(h.counts[i])), colour, h.counts[i]);
    }
    svg += fmt::format("<text x=\"160\" y=\"14\" class=\"axis\" text-anchor=\"middle\">{}</text>",
                       escape(title));
  }
  return svg + "</svg>";
}

std::string histogram_section(const ReportData& d) {
  std::string s = "<div class=\"row\">";
  if (!d.error_before.empty())
    s += histogram_svg("fig-histogram-before", d.histogram_before, kBefore, "before calibration");
  s += histogram_svg("fig-histogram", d.histogram_after, kAfter, "after calibration");
  s += "</div>";
  return "<figure>" + s +
         "<figcaption>How many poses have which position error, before and after calibration "
         "(note the different scales). A narrow peak near zero is good; a long tail to the right "
         "means a few poses are much worse than the rest.</figcaption></figure>\n";
}

std::string map_svg(const std::string& id, const calib::ErrorGrid& g, double scale_max,
                    const std::vector<Eigen::Vector2d>& measured, const std::string& title,
                    const std::string& xlabel, const std::string& ylabel) {
  std::string svg = svg_open(id, 320, 300, title);
  if (g.nx > 0 && g.ny > 0) {
    Frame f;
    f.x0 = 56;
    f.y0 = 24;
    f.w = 240;
    f.h = 220;
    f.xlo = g.lo.x();
    f.xhi = g.lo.x() + g.cell.x() * g.nx;
    f.ylo = g.lo.y();
    f.yhi = g.lo.y() + g.cell.y() * g.ny;
    // Drawn with the second coordinate growing downwards (image-like: camera y points down).
    const auto py = [&](double y) { return f.y0 + (y - f.ylo) / (f.yhi - f.ylo) * f.h; };
    for (int iy = 0; iy < g.ny; ++iy)
      for (int ix = 0; ix < g.nx; ++ix) {
        const auto i = static_cast<std::size_t>(iy * g.nx + ix);
        if (g.count[i] == 0) continue;
        const double x = g.lo.x() + g.cell.x() * ix, y = g.lo.y() + g.cell.y() * iy;
        svg += fmt::format(
            "<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" "
            "fill=\"{}\"><title>{} ({} poses)</title></rect>",
            f.px(x), py(y), f.px(x + g.cell.x()) - f.px(x) + 0.3, py(y + g.cell.y()) - py(y) + 0.3,
            scale_colour(g.rms[i] / scale_max), escape(length(g.rms[i])), g.count[i]);
      }
    svg += "\n";
    for (const auto& m : measured)
      svg += fmt::format(
          "<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"2.5\" fill=\"#fff\" "
          "stroke=\"#000\" stroke-width=\"0.8\"/>",
          f.px(m.x()), py(m.y()));
    svg += fmt::format(
        "\n<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" "
        "stroke=\"#444\"/>\n",
        f.x0, f.y0, f.w, f.h);
    for (const double t : ticks(f.xlo * 1e3, f.xhi * 1e3, 4))
      svg += fmt::format(
          "<text x=\"{:.1f}\" y=\"{:.1f}\" class=\"tick\" "
          "text-anchor=\"middle\">{:.0f}</text>",
          f.px(t * 1e-3), f.y0 + f.h + 14, t);
    for (const double t : ticks(f.ylo * 1e3, f.yhi * 1e3, 4))
      svg += fmt::format(
          "<text x=\"{:.1f}\" y=\"{:.1f}\" class=\"tick\" "
          "text-anchor=\"end\">{:.0f}</text>",
          f.x0 - 4, py(t * 1e-3) + 4, t);
    svg += fmt::format(
        "\n<text x=\"{:.1f}\" y=\"{:.1f}\" class=\"axis\" "
        "text-anchor=\"middle\">{}</text>",
        f.x0 + f.w / 2, f.y0 + f.h + 30, escape(xlabel));
    svg += fmt::format(
        "<text x=\"12\" y=\"{0:.1f}\" class=\"axis\" text-anchor=\"middle\" "
        "transform=\"rotate(-90 12 {0:.1f})\">{1}</text>",
        f.y0 + f.h / 2, escape(ylabel));
    svg +=
        fmt::format("<text x=\"{:.1f}\" y=\"14\" class=\"axis\" text-anchor=\"middle\">{}</text>\n",
                    f.x0 + f.w / 2, escape(title));
  }
  return svg + "</svg>";
}

std::string colour_bar(double scale_max) {
  std::string svg = svg_open("fig-map-scale", 320, 50, "colour scale");
  for (int i = 0; i < 50; ++i)
    svg += fmt::format("<rect x=\"{}\" y=\"6\" width=\"5.2\" height=\"14\" fill=\"{}\"/>",
                       30 + i * 5, scale_colour(i / 49.0));
  svg += fmt::format(
      "<text x=\"30\" y=\"34\" class=\"tick\">0</text><text x=\"280\" y=\"34\" "
      "class=\"tick\" text-anchor=\"end\">{} or more</text>",
      escape(length(scale_max)));
  return svg + "</svg>";
}

std::string map_section(const ReportData& d) {
  if (!d.has_map)
    return "<p id=\"fig-map-top\" class=\"missing\">No error map: this session has no held-out "
           "poses with known positions.</p><p id=\"fig-map-side\"></p>\n";
  // One colour scale for the maps after calibration; the maps before use their own (they would
  // saturate it), stated in their captions.
  const double after_max = std::max({d.top_after.max_rms(), d.side_after.max_rms(), 1e-9});
  const double before_max = std::max({d.top_before.max_rms(), d.side_before.max_rms(), 1e-9});
  std::string s = "<div class=\"row\">";
  s += map_svg("fig-map-top", d.top_after, after_max, d.measured_top, "after: seen from above",
               "x across the camera image (mm)", "z away from camera 0 (mm)");
  s +=
      map_svg("fig-map-side", d.side_after, after_max, d.measured_side, "after: seen from the side",
              "z away from camera 0 (mm)", "y down the camera image (mm)");
  s += "</div>" + colour_bar(after_max);
  std::string before;
  if (d.top_before.nx > 0) {
    before = "<div class=\"row\">";
    before += map_svg("fig-map-top-before", d.top_before, before_max, d.measured_top,
                      "before: seen from above", "x across the camera image (mm)",
                      "z away from camera 0 (mm)");
    before += map_svg("fig-map-side-before", d.side_before, before_max, d.measured_side,
                      "before: seen from the side", "z away from camera 0 (mm)",
                      "y down the camera image (mm)");
    before += "</div>" + colour_bar(before_max);
  }
  return figure(s,
                "Where in the workspace the calibrated robot is accurate: each square is the "
                "RMS position error of the " +
                    escape(d.map_source) +
                    " in it, after calibration (colour scale below). White dots are the poses "
                    "that were measured for the calibration; the error usually grows away from "
                    "them. Positions are in camera 0's frame, in millimetres.") +
         (before.empty() ? std::string()
                         : figure(before,
                                  "The same maps before calibration (their own colour scale: the "
                                  "errors are much larger)."));
}

// A parameter by its label, with its name in the robot file as a tooltip.
std::string name_html(const ReportName& n) {
  if (n.raw.empty() || n.raw == n.label) return escape(n.label);
  return fmt::format("<span class=\"param\" title=\"{}\">{}</span>", escape(n.raw),
                     escape(n.label));
}

std::string sentence_html(const ReportSentence& sentence) {
  std::string s;
  for (const auto& part : sentence) s += part.raw.empty() ? escape(part.label) : name_html(part);
  return s;
}

std::string parameter_section(const ReportData& d) {
  std::string s = fmt::format(
      "<p>{} The interval is where the true value lies with 95 % confidence. Values in mm "
      "(lengths) and degrees (angles); the last column is the parameter's name in the robot "
      "file and in results/identification.json.</p>\n<table id=\"fig-parameters\" "
      "class=\"num\"><tr><th>parameter</th><th>drawing</th><th>calibrated</th><th>change</th>"
      "<th>± (95 %)</th><th>notes</th><th>name</th></tr>\n",
      escape(d.parameter_counts));
  for (const auto& p : d.parameters) {
    std::string notes;
    if (!p.stands_for.empty()) {
      notes = "stands in for " + name_html(p.stands_for[0]);
      for (std::size_t k = 1; k < std::min<std::size_t>(p.stands_for.size(), 3); ++k)
        notes += ", " + name_html(p.stands_for[k]);
      if (p.stands_for.size() > 3) notes += fmt::format(" and {} more", p.stands_for.size() - 3);
      notes += ": its change is their combination";
    }
    if (p.strongly_correlated)
      notes += (notes.empty() ? "" : "; ") + std::string("strongly correlated (below)");
    s += fmt::format(
        "<tr><td class=\"l\">{}</td><td>{:.4f} {}</td><td>{:.4f} {}</td><td>{:+.4f} {}</td>"
        "<td>{:.4f} {}</td><td class=\"l\">{}</td><td class=\"l raw\">{}</td></tr>\n",
        name_html(p.name), p.nominal, p.unit, p.value, p.unit, p.change, p.unit, p.ci95, p.unit,
        notes, escape(p.name.raw));
  }
  s += "</table>\n";
  s += "<h3>Strongly correlated pairs</h3>\n<table id=\"fig-correlations\" class=\"num\"><tr>"
       "<th>parameter</th><th>parameter</th><th>correlation</th></tr>\n";
  for (const auto& c : d.correlations)
    s += fmt::format("<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{:+.3f}</td></tr>\n",
                     name_html(c.first), name_html(c.second), c.r);
  if (d.correlations.empty()) s += "<tr><td colspan=\"3\" class=\"l\">none</td></tr>\n";
  s += "</table><p class=\"cap\">Two parameters with a correlation near ±1 are hard to tell apart "
       "with these measurements: their errors compensate each other. Each is still usable inside "
       "the model, but not as a separate measurement of that part of the robot.</p>\n";
  return s;
}

std::string not_identified_section(const ReportData& d) {
  std::string s = fmt::format(
      "<div id=\"fig-not-identified\"><p>{} A held parameter keeps the value of the robot's "
      "drawing. Either the measured poses do not move it at all, or it moves the measurements "
      "exactly like a combination of identified parameters, so only the combination can be "
      "known (those parameters then stand in for it). Point at a parameter for its name in the "
      "robot file.</p><ul>\n",
      escape(d.held_counts));
  // The first reasons in view; the rest folded (a <details> element: no script needed).
  constexpr std::size_t kShown = 6;
  for (std::size_t i = 0; i < d.not_identified.size() && i < kShown; ++i)
    s += "<li>" + sentence_html(d.not_identified[i]) + "</li>\n";
  s += "</ul>\n";
  if (d.not_identified.size() > kShown) {
    s += fmt::format("<details><summary>{} more reasons</summary><ul>\n",
                     d.not_identified.size() - kShown);
    for (std::size_t i = kShown; i < d.not_identified.size(); ++i)
      s += "<li>" + sentence_html(d.not_identified[i]) + "</li>\n";
    s += "</ul></details>\n";
  }
  if (!d.identification_notes.empty()) {
    s += "<p>The analysis also says:</p><ul>\n";
    for (const auto& note : d.identification_notes) s += "<li>" + sentence_html(note) + "</li>\n";
    s += "</ul>\n";
  }
  return s + "</div>\n";
}

std::string camera_section(const ReportData& d) {
  if (d.cameras.empty())
    return "<p id=\"fig-cameras\" class=\"missing\">This session has no camera observations "
           "(the poses were measured by another instrument), so there is no coverage or "
           "reprojection map.</p>\n";
  double rms_max = 1e-6;
  for (const auto& c : d.cameras)
    for (const double r : c.pose_rms_px) rms_max = std::max(rms_max, r);
  std::string s = "<div id=\"fig-cameras\" class=\"row\">";
  for (std::size_t i = 0; i < d.cameras.size(); ++i) {
    const auto& c = d.cameras[i];
    const double scale = 300.0 / std::max(c.width, 1);
    const double w = 300.0, h = c.height * scale;
    std::string svg = svg_open(fmt::format("fig-camera-{}", i), 320, static_cast<int>(h) + 40,
                               "camera " + c.name);
    svg += fmt::format("<text x=\"10\" y=\"14\" class=\"axis\">{} ({} × {} px)</text>",
                       escape(c.name), c.width, c.height);
    svg += fmt::format(
        "<rect x=\"10\" y=\"22\" width=\"{:.0f}\" height=\"{:.1f}\" fill=\"#f4f4f4\" "
        "stroke=\"#444\"/>\n<path d=\"",
        w, h);
    for (const auto& p : c.corners)
      svg += fmt::format("M{:.1f} {:.1f}h0", 10 + p.x() * scale, 22 + p.y() * scale);
    svg += "\" stroke=\"#b0b0b0\" stroke-width=\"1.5\" stroke-linecap=\"round\"/>\n";
    for (std::size_t k = 0; k < c.pose_centres.size() && k < c.pose_rms_px.size(); ++k)
      svg += fmt::format(
          "<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"4\" fill=\"{}\" stroke=\"#000\" "
          "stroke-width=\"0.5\"><title>{:.3f} px</title></circle>",
          10 + c.pose_centres[k].x() * scale, 22 + c.pose_centres[k].y() * scale,
          scale_colour(c.pose_rms_px[k] / rms_max), c.pose_rms_px[k]);
    s += svg + "</svg>\n";
  }
  s += "</div>";
  std::string bar = svg_open("fig-reprojection-scale", 320, 50, "reprojection colour scale");
  for (int i = 0; i < 50; ++i)
    bar += fmt::format("<rect x=\"{}\" y=\"6\" width=\"5.2\" height=\"14\" fill=\"{}\"/>",
                       30 + i * 5, scale_colour(i / 49.0));
  bar += fmt::format(
      "<text x=\"30\" y=\"34\" class=\"tick\">0 px</text><text x=\"280\" y=\"34\" "
      "class=\"tick\" text-anchor=\"end\">{:.3f} px</text></svg>",
      rms_max);
  return figure(s + bar,
                "Camera coverage: every grey dot is a board corner a camera detected; the image "
                "should be covered well, corners included. Reprojection: each circle is one "
                "robot pose, placed where its board appeared, coloured by how far the detected "
                "corners lie from where the measured board pose puts them (RMS in pixels, all "
                "cameras of that pose). Bright circles are poses measured less well.");
}

std::string axis_name(int i) {
  return std::array<const char*, 3>{"x", "y", "z"}[static_cast<std::size_t>(i)];
}

std::string diagnostics_section(const ReportData& d) {
  std::string s = "<div id=\"fig-diagnostics\">";
  s += "<p>If the model describes the robot completely, the errors that remain are noise: they "
       "do not depend on where the robot is. An error that grows with position points to "
       "something the model lacks (for example a tilted tool absorbed into arm lengths, a "
       "sagging arm, or a loose joint). Below, each error direction (camera 0's frame) is "
       "compared with each position coordinate, and with the load each actuator carries at that "
       "pose (the effort that holds a weight at the tool, from the calibrated model): an error "
       "that follows the load rather than the position points to flexible joints, gears or belts, "
       "or a payload the model lacks. A trend is flagged when it is statistically significant "
       "(family-wise 1 % level over the pairs of each table). The unmodelled effect may be in the "
       "robot or in the measurement (for example a camera calibration that scales depth).</p>\n";
  if (d.diagnostics.empty()) s += "<p class=\"missing\">No residuals to test.</p>";
  for (const auto& diag : d.diagnostics) {
    const auto& t = diag.trends;
    s += fmt::format("<h3>{} ({} poses)</h3>\n", escape(diag.source), t.n);
    double largest = 0.0;
    for (const auto& tr : t.trends)
      if (tr.significant) largest = std::max(largest, tr.amplitude);
    s += t.unmodelled_error_suspected()
             ? fmt::format(
                   "<p class=\"warn\">Unmodelled error suspected: the remaining error "
                   "changes systematically, by up to {} across the "
                   "measured poses (red rows).</p>",
                   escape(length(largest)))
             : "<p class=\"ok\">No trend: the remaining error looks like noise.</p>";
    s += "<table class=\"num\"><tr><th>error along</th><th>compared with</th><th>correlation</th>"
         "<th>p-value</th><th>change over the workspace</th><th>verdict</th></tr>\n";
    for (const auto& tr : t.trends)
      s += fmt::format(
          "<tr{}><td>{}</td><td>{}</td><td>{:+.2f}</td><td>{:.2g}</td><td>{}</td>"
          "<td class=\"l\">{}</td></tr>\n",
          tr.significant ? " class=\"flag\"" : "", axis_name(tr.component),
          escape(t.variables[static_cast<std::size_t>(tr.variable)]), tr.correlation.r,
          tr.correlation.p_value, escape(length(tr.amplitude)),
          tr.significant ? "trend: unmodelled error" : "noise");
    s += "</table>\n";
  }
  return s + "</div>\n";
}

std::string timings_section(const ReportData& d) {
  std::string s =
      "<table id=\"fig-timings\" class=\"num\"><tr><th>step</th><th>seconds</th></tr>\n";
  for (const auto& [name, seconds] : d.timings)
    s += fmt::format("<tr><td class=\"l\">{}</td><td>{:.2f}</td></tr>\n", escape(name), seconds);
  return s + "</table>\n";
}

constexpr const char* kStyle = R"(
body{font-family:sans-serif;max-width:1000px;margin:1em auto;padding:0 1em;color:#222}
h1{font-size:1.5em}h2{margin-top:1.6em;border-bottom:1px solid #ccc}h3{font-size:1.05em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 6px}
table.num td{text-align:right;white-space:nowrap}table.num td.l{text-align:left;white-space:normal}th{background:#eee}
figure{margin:1em 0}figcaption,.cap{font-size:.9em;color:#444;max-width:820px}
.row{display:flex;flex-wrap:wrap;gap:8px}.tick{font-size:10px;fill:#333}.axis{font-size:11px;fill:#111}
.verdict{font-size:1.15em;padding:.5em;background:#eef5fb;border-left:4px solid #1f6fb2}
.warn{color:#a40000;font-weight:bold}.ok{color:#1b6e1b}.missing{color:#666;font-style:italic}
tr.flag td{background:#fde8e8}.param{border-bottom:1px dotted #888}td.raw{color:#666;font-size:.85em}
)";

}  // namespace

const std::vector<std::string>& report_figure_ids() {
  static const std::vector<std::string> ids = {
      "fig-accuracy", "fig-per-pose",    "fig-histogram",    "fig-map-top",
      "fig-map-side", "fig-parameters",  "fig-correlations", "fig-not-identified",
      "fig-cameras",  "fig-diagnostics", "fig-timings"};
  return ids;
}

std::string render_report_page(const ReportData& d) {
  std::string html = "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">";
  html += "<title>Calibration report: " + escape(d.robot) + "</title><style>" + kStyle +
          "</style></head><body>\n";
  html += fmt::format("<h1>Calibration report: {}</h1>\n<p>Session {} · {}</p>\n", escape(d.robot),
                      escape(d.session), escape(d.software));
  html += "<p class=\"verdict\">" + escape(d.verdict) + "</p>\n";
  html += "<h2>1. Accuracy before and after</h2>\n" + accuracy_section(d);
  html += "<h2>2. Error of each pose</h2>\n" + per_pose_section(d);
  html += "<h2>3. How the errors are spread</h2>\n" + histogram_section(d);
  html += "<h2>4. Error over the workspace</h2>\n" + map_section(d);
  html += "<h2>5. Calibrated parameters</h2>\n" + parameter_section(d);
  html += "<h2>6. What could not be identified</h2>\n" + not_identified_section(d);
  html += "<h2>7. Cameras: coverage and reprojection</h2>\n" + camera_section(d);
  html += "<h2>8. Is anything left unmodelled?</h2>\n" + diagnostics_section(d);
  html += "<h2>9. Time taken</h2>\n" + timings_section(d);
  html += "</body></html>\n";
  return html;
}

}  // namespace robocal::app
