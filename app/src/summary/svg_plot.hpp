#pragma once
// The report page's drawing toolkit: HTML escaping, lengths for people, axis ticks, a colour
// scale and SVG axes/legends. Pure string builders (no I/O); report_page.cpp lays the figures out
// with them.
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace robocal::app::svg {

// Text safe inside HTML and SVG attributes.
std::string escape(const std::string& s);

// A length for people: µm below a millimetre, mm above.
std::string length(double m);

// Axis ticks: about `target` round numbers covering [lo, hi].
std::vector<double> ticks(double lo, double hi, int target);
// Ticks for a count (poses, a histogram's bars): whole numbers only, so a few poses do not get
// the labels 0, 0, 1, 1, 2 of half steps.
std::vector<double> count_ticks(double hi, int target);

// Decades from below `lo` to `hi` (a log10 axis).
std::vector<double> log_ticks(double lo, double hi);

// Colour of a value in [0, 1] on a perceptually ordered scale (dark blue -> green -> yellow).
std::string scale_colour(double t);

// A plot area inside an SVG: data coordinates -> pixels, linear or log10 on y.
struct Frame {
  double x0 = 60, y0 = 20, w = 520, h = 220;  // plot area in px
  double xlo = 0, xhi = 1, ylo = 0, yhi = 1;
  bool log_y = false;
  [[nodiscard]] double px(double x) const;
  [[nodiscard]] double py(double y) const;
};

std::string svg_open(const std::string& id, int width, int height, const std::string& title);

// Axes with tick labels, each label through `xtext` / `ytext`.
std::string axes(const Frame& f, const std::vector<double>& xticks,
                 const std::vector<double>& yticks, const std::string& xlabel,
                 const std::string& ylabel, const std::function<std::string(double)>& xtext,
                 const std::function<std::string(double)>& ytext);

// A column of colour swatches with their labels, from (x, y) down.
std::string legend(double x, double y,
                   const std::vector<std::pair<std::string, std::string>>& items);

// An SVG with its caption.
std::string figure(const std::string& svg, const std::string& caption);

}  // namespace robocal::app::svg
