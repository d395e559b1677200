#pragma once
// Progress output for long steps. On a terminal it redraws one line ("\r"); when stderr is a file
// or a pipe (CI, batch logs) it prints a line at every 10 % so logs stay readable.
#include <chrono>
#include <cstdio>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace robocal::app {

class ProgressBar {
 public:
  // `total` units of work; `stream` is where the bar goes (stderr by default).
  ProgressBar(std::string label, std::size_t total, std::FILE* stream = stderr);
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;
  ~ProgressBar();

  void advance(std::size_t units = 1);
  // Ends the bar with a closing message (e.g. "60 poses, 2 rejected").
  void finish(const std::string& message = {});

  [[nodiscard]] std::size_t done() const { return done_; }

 private:
  void draw(bool final_line);

  std::string label_;
  std::size_t total_;
  std::size_t done_ = 0;
  int last_decile_ = 0;  // no line for 0 %: the first line comes at 10 %
  bool interactive_;
  bool finished_ = false;
  std::FILE* stream_;
  std::chrono::steady_clock::time_point start_;
};

// A progress bar that exists only when there is somewhere to print (out == nullptr: silent, e.g.
// sessions processed in parallel); advance() may be called from any thread.
class StageProgress {
 public:
  StageProgress(std::FILE* out, const std::string& label, std::size_t total);
  void advance();
  void finish(const std::string& message);

 private:
  std::optional<ProgressBar> bar_;
  std::mutex mutex_;
};

// Times the named stages of a pipeline and prints a closing table.
class StageClock {
 public:
  void start(std::string name);
  void stop();
  [[nodiscard]] std::string table() const;
  [[nodiscard]] double total_seconds() const;
  struct Stage {
    std::string name;
    double seconds = 0;
  };
  [[nodiscard]] const std::vector<Stage>& stages() const { return stages_; }

 private:
  std::vector<Stage> stages_;
  std::chrono::steady_clock::time_point started_;
  bool running_ = false;
};

}  // namespace robocal::app
