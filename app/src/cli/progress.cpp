#include "cli/progress.hpp"

#include <fmt/core.h>
#include <unistd.h>

#include <algorithm>

namespace robocal::app {

namespace {
constexpr int kBarWidth = 30;

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

ProgressBar::ProgressBar(std::string label, std::size_t total, std::FILE* stream)
    : label_(std::move(label)),
      total_(std::max<std::size_t>(total, 1)),
      interactive_(isatty(fileno(stream)) != 0),
      stream_(stream),
      start_(std::chrono::steady_clock::now()) {
  draw(false);
}

ProgressBar::~ProgressBar() {
  if (!finished_) finish();
}

void ProgressBar::advance(std::size_t units) {
  done_ = std::min(total_, done_ + units);
  draw(false);
}

void ProgressBar::finish(const std::string& message) {
  if (finished_) return;
  finished_ = true;
  const double elapsed = seconds_since(start_);
  if (interactive_) std::fputs("\r\033[K", stream_);
  fmt::print(stream_, "{}: {}/{} done in {:.1f} s{}{}\n", label_, done_, total_, elapsed,
             message.empty() ? "" : " — ", message);
  std::fflush(stream_);
}

void ProgressBar::draw(bool final_line) {
  const double fraction = static_cast<double>(done_) / static_cast<double>(total_);
  if (interactive_) {
    const int filled = static_cast<int>(fraction * kBarWidth);
    const double elapsed = seconds_since(start_);
    const double eta = done_ > 0 ? elapsed * (1.0 - fraction) / fraction : 0.0;
    // No estimate before the first item is done (nothing to extrapolate from).
    const std::string left = done_ > 0 ? fmt::format("eta {:.0f} s", eta) : "eta --";
    fmt::print(stream_, "\r\033[K{} [{}{}] {}/{} {:3.0f}%  {}", label_,
               std::string(static_cast<std::size_t>(filled), '#'),
               std::string(static_cast<std::size_t>(kBarWidth - filled), '.'), done_, total_,
               100.0 * fraction, left);
    std::fflush(stream_);
    return;
  }
  const int decile = static_cast<int>(fraction * 10.0);
  if (decile != last_decile_ && !final_line && done_ > 0 && done_ < total_) {
    last_decile_ = decile;
    fmt::print(stream_, "{}: {}/{} ({:.0f}%)\n", label_, done_, total_, 100.0 * fraction);
    std::fflush(stream_);
  }
}

void StageClock::start(std::string name) {
  if (running_) stop();
  stages_.push_back({std::move(name), 0.0});
  started_ = std::chrono::steady_clock::now();
  running_ = true;
}

void StageClock::stop() {
  if (!running_) return;
  stages_.back().seconds = seconds_since(started_);
  running_ = false;
}

double StageClock::total_seconds() const {
  double total = 0;
  for (const Stage& s : stages_) total += s.seconds;
  return total;
}

std::string StageClock::table() const {
  std::string out;
  for (const Stage& s : stages_) out += fmt::format("  {:<34} {:8.2f} s\n", s.name, s.seconds);
  out += fmt::format("  {:<34} {:8.2f} s\n", "total", total_seconds());
  return out;
}

StageProgress::StageProgress(std::FILE* out, const std::string& label, std::size_t total) {
  if (out) bar_.emplace(label, total, out);
}

void StageProgress::advance() {
  const std::lock_guard<std::mutex> lock(mutex_);
  if (bar_) bar_->advance();
}

void StageProgress::finish(const std::string& message) {
  const std::lock_guard<std::mutex> lock(mutex_);
  if (bar_) bar_->finish(message);
}

}  // namespace robocal::app
