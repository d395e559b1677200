#include "summary/svg_plot.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace robocal::app::svg {

std::string escape(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  for (const char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// A length for people: µm below a millimetre, mm above.
std::string length(double m) {
  if (std::abs(m) < 1e-3) return fmt::format("{:.1f} µm", m * 1e6);
  return fmt::format("{:.2f} mm", m * 1e3);
}

// Axis ticks: about `target` round numbers covering [lo, hi].
std::vector<double> ticks(double lo, double hi, int target) {
  const double span = std::max(hi - lo, 1e-300);
  const double raw = span / std::max(target, 1);
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  double step = magnitude;
  for (const double m : {1.0, 2.0, 5.0, 10.0})
    if (m * magnitude >= raw) {
      step = m * magnitude;
      break;
    }
  std::vector<double> out;
  for (double t = std::ceil(lo / step) * step; t <= hi + step * 1e-9; t += step) out.push_back(t);
  return out;
}

std::vector<double> count_ticks(double hi, int target) {
  std::vector<double> out;
  for (const double t : ticks(0.0, hi, target))
    if (t == std::floor(t)) out.push_back(t);
  return out;
}

// Colour of a value in [0, 1] on a perceptually ordered scale (dark blue -> green -> yellow).
std::string scale_colour(double t) {
  static const std::array<std::array<double, 3>, 5> stops = {
      {{68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}}};
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0) * 4.0;
  const auto i = std::min<std::size_t>(static_cast<std::size_t>(t), 3);
  const double f = t - static_cast<double>(i);
  std::array<int, 3> c{};
  for (std::size_t k = 0; k < 3; ++k)
    c[k] = static_cast<int>(std::lround(stops[i][k] + f * (stops[i + 1][k] - stops[i][k])));
  return fmt::format("#{:02x}{:02x}{:02x}", c[0], c[1], c[2]);
}

double Frame::px(double x) const {
  return x0 + (x - xlo) / (xhi - xlo) * w;
}

double Frame::py(double y) const {
  if (log_y) {
    const double l = std::log10(std::max(y, 1e-300));
    return y0 + h - (l - std::log10(ylo)) / (std::log10(yhi) - std::log10(ylo)) * h;
  }
  return y0 + h - (y - ylo) / (yhi - ylo) * h;
}

std::string svg_open(const std::string& id, int width, int height, const std::string& title) {
  return fmt::format(
      "<svg id=\"{}\" width=\"{}\" height=\"{}\" "
      "viewBox=\"0 0 {} {}\" role=\"img\" aria-label=\"{}\">\n",
      id, width, height, width, height, escape(title));
}

// Axes with tick labels; y labels through `ylabel_of` (values in metres shown as µm/mm).
std::string axes(const Frame& f, const std::vector<double>& xticks,
                 const std::vector<double>& yticks, const std::string& xlabel,
                 const std::string& ylabel, const std::function<std::string(double)>& xtext,
                 const std::function<std::string(double)>& ytext) {
  std::string s = fmt::format(
      "<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" fill=\"none\" "
      "stroke=\"#444\"/>\n",
      f.x0, f.y0, f.w, f.h);
  for (const double t : xticks) {
    const double x = f.px(t);
    s += fmt::format(
        "<line x1=\"{0:.1f}\" y1=\"{1:.1f}\" x2=\"{0:.1f}\" y2=\"{2:.1f}\" stroke=\"#ddd\"/>"
        "<text x=\"{0:.1f}\" y=\"{3:.1f}\" class=\"tick\" text-anchor=\"middle\">{4}</text>\n",
        x, f.y0, f.y0 + f.h, f.y0 + f.h + 14, escape(xtext(t)));
  }
  for (const double t : yticks) {
    const double y = f.py(t);
    s += fmt::format(
        "<line x1=\"{1:.1f}\" y1=\"{0:.1f}\" x2=\"{2:.1f}\" y2=\"{0:.1f}\" stroke=\"#ddd\"/>"
        "<text x=\"{3:.1f}\" y=\"{4:.1f}\" class=\"tick\" text-anchor=\"end\">{5}</text>\n",
        y, f.x0, f.x0 + f.w, f.x0 - 4, y + 4, escape(ytext(t)));
  }
  s += fmt::format(
      "<text x=\"{:.1f}\" y=\"{:.1f}\" class=\"axis\" text-anchor=\"middle\">{}</text>\n",
      f.x0 + f.w / 2, f.y0 + f.h + 32, escape(xlabel));
  s += fmt::format(
      "<text x=\"14\" y=\"{0:.1f}\" class=\"axis\" text-anchor=\"middle\" "
      "transform=\"rotate(-90 14 {0:.1f})\">{1}</text>\n",
      f.y0 + f.h / 2, escape(ylabel));
  return s;
}

std::vector<double> log_ticks(double lo, double hi) {
  std::vector<double> out;
  for (double d = std::pow(10.0, std::floor(std::log10(lo))); d <= hi * 1.0001; d *= 10.0)
    if (d >= lo * 0.9999) out.push_back(d);
  return out;
}

std::string legend(double x, double y,
                   const std::vector<std::pair<std::string, std::string>>& items) {
  std::string s;
  for (const auto& [colour, text] : items) {
    s += fmt::format(
        "<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"12\" height=\"12\" fill=\"{}\"/>"
        "<text x=\"{:.1f}\" y=\"{:.1f}\" class=\"tick\">{}</text>\n",
        x, y, colour, x + 16, y + 10, escape(text));
    y += 16;
  }
  return s;
}

std::string figure(const std::string& svg, const std::string& caption) {
  return "<figure>" + svg + "<figcaption>" + caption + "</figcaption></figure>\n";
}

}  // namespace robocal::app::svg
