// Numeric expressions in robot files: exact values such as -2*pi/3 or 0.196*sqrt(3)/2.
#include "robocal/calib/robot_file.hpp"

#include <cctype>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace robocal::calib {
namespace {

class ExpressionParser {
 public:
  explicit ExpressionParser(const std::string& text) : text_(text) {}

  double parse() {
    const double v = sum();
    skip_space();
    if (pos_ != text_.size()) fail("unexpected '" + text_.substr(pos_, 1) + "'");
    return v;
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    throw std::invalid_argument("bad number \"" + text_ + "\": " + what);
  }
  void skip_space() {
    while (pos_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[pos_]))) ++pos_;
  }
  bool accept(char c) {
    skip_space();
    if (pos_ < text_.size() && text_[pos_] == c) {
      ++pos_;
      return true;
    }
    return false;
  }
  double sum() {
    double v = product();
    for (;;) {
      if (accept('+')) {
        v += product();
      } else if (accept('-')) {
        v -= product();
      } else {
        return v;
      }
    }
  }
  double product() {
    double v = unary();
    for (;;) {
      if (accept('*')) {
        v *= unary();
      } else if (accept('/')) {
        v /= unary();
      } else {
        return v;
      }
    }
  }
  double unary() {
    if (accept('-')) return -unary();
    if (accept('+')) return unary();
    return power();
  }
  double power() {
    const double base = primary();
    if (accept('^')) return std::pow(base, unary());
    return base;
  }
  double primary() {
    skip_space();
    if (pos_ >= text_.size()) fail("expression ends too early");
    if (accept('(')) {
      const double v = sum();
      if (!accept(')')) fail("missing ')'");
      return v;
    }
    const char c = text_[pos_];
    if (std::isdigit(static_cast<unsigned char>(c)) || c == '.') {
      std::size_t used = 0;
      double v = 0.0;
      try {
        v = std::stod(text_.substr(pos_), &used);
      } catch (const std::exception&) {
        fail("not a number");
      }
      pos_ += used;
      return v;
    }
    if (std::isalpha(static_cast<unsigned char>(c))) {
      const std::size_t start = pos_;
      while (pos_ < text_.size() &&
             (std::isalnum(static_cast<unsigned char>(text_[pos_])) || text_[pos_] == '_'))
        ++pos_;
      const std::string name = text_.substr(start, pos_ - start);
      if (name == "pi") return std::numbers::pi;
      if (name == "sqrt" || name == "sin" || name == "cos" || name == "deg") {
        if (!accept('(')) fail("'" + name + "' needs '('");
        const double arg = sum();
        if (!accept(')')) fail("missing ')'");
        if (name == "sqrt") {
          if (arg < 0) fail("sqrt of a negative number");
          return std::sqrt(arg);
        }
        if (name == "sin") return std::sin(arg);
        if (name == "cos") return std::cos(arg);
        return arg * std::numbers::pi / 180.0;
      }
      fail("unknown name '" + name + "' (allowed: pi, sqrt, sin, cos, deg)");
    }
    fail("unexpected '" + std::string(1, c) + "'");
  }

  const std::string& text_;
  std::size_t pos_ = 0;
};

}  // namespace

double evaluate_expression(const std::string& text) {
  const double v = ExpressionParser(text).parse();
  if (!std::isfinite(v)) throw std::invalid_argument("bad number \"" + text + "\": not finite");
  return v;
}

}  // namespace robocal::calib
