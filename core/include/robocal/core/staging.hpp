#pragma once
// Results replaced whole or not at all. A folder of results (a session's results/, a simulated
// session) is written into a staging folder beside it and replaces the old folder in one step
// (an atomic exchange) when the writer commits; several loose files (a command's output and its
// report) are written as temporaries and renamed together once all of them are written. A writer
// that throws, is interrupted (the signal handler removes the staging, core/interrupt_cleanup.hpp)
// or is killed leaves the previous results exactly as they were; a staging folder a killed
// process left is removed by the next writer of the same target.
#include "robocal/core/interrupt_cleanup.hpp"

#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace robocal::core {

class StagedDirectory {
 public:
  enum class Start {
    kEmpty,         // a new folder (a simulated session)
    kCopyOfTarget,  // the target's files (but leftover "*.tmp" and `leave_out`)
  };
  // Stages a replacement for `target`: removes staging folders of `target` that processes no
  // longer running left, then creates the staging folder "<parent>/.<name>.staging-<pid>-<n>/"
  // holding path() = ".../<name>". `leave_out`: files and folders of the target (relative paths)
  // the copy does not take, those the new content makes stale. Throws InputError naming the
  // folder and the cause when the target exists and is not a folder, when the staging folder
  // cannot be created or the target cannot be copied.
  StagedDirectory(std::filesystem::path target, Start start,
                  const std::vector<std::filesystem::path>& leave_out = {});
  // Not committed: the staging folder is removed (the target is untouched).
  ~StagedDirectory();
  StagedDirectory(const StagedDirectory&) = delete;
  StagedDirectory& operator=(const StagedDirectory&) = delete;
  StagedDirectory(StagedDirectory&&) = delete;
  StagedDirectory& operator=(StagedDirectory&&) = delete;

  // Where the replacement is written; it has the target's name.
  [[nodiscard]] const std::filesystem::path& path() const { return staged_; }
  // The staging folder that holds path(): a stand-in for the target's parent.
  [[nodiscard]] const std::filesystem::path& root() const { return root_; }
  [[nodiscard]] const std::filesystem::path& target() const { return target_; }

  // Replaces the target with path() in one step (renameat2's exchange; where the file system
  // cannot exchange, two renames) and removes the old content. Throws InputError naming the
  // target when it cannot be replaced; the target is then unchanged.
  void commit();

 private:
  std::filesystem::path target_, root_, staged_;
  std::unique_ptr<RemoveOnInterrupt> cleanup_;
  bool committed_ = false;
};

// Several files replaced together: each is written to "<path>.tmp", and only when every one is
// written are they renamed over their paths. A write that fails (a full disk, a folder given as
// the file, no permission) removes every temporary and throws InputError naming the file and the
// cause: no file was replaced.
class StagedFiles {
 public:
  // Throws InputError when `path` is a folder (the file name is missing).
  void add(const std::filesystem::path& path, std::string bytes);
  void commit();

 private:
  std::vector<std::pair<std::filesystem::path, std::string>> files_;
};

}  // namespace robocal::core
