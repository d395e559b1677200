#pragma once
// What an interruption (Ctrl-C, SIGTERM) removes before the process exits: the temporary files
// and staging folders of writes that had not finished. A command's signal handler calls
// remove_unfinished_writes(), which is async-signal-safe (system calls only: no allocation, no
// locks), then exits. A kill that no handler sees (SIGKILL) leaves them; the next writer of the
// same target removes them (core/staging.hpp).
#include <filesystem>

namespace robocal::core {

// Registers `path` (a file or a folder, removed whole) for removal on interruption while the
// object lives. Registering never fails: when every slot is taken the path is simply not
// registered, and the next run removes what is left.
class RemoveOnInterrupt {
 public:
  explicit RemoveOnInterrupt(const std::filesystem::path& path);
  ~RemoveOnInterrupt();
  RemoveOnInterrupt(const RemoveOnInterrupt&) = delete;
  RemoveOnInterrupt& operator=(const RemoveOnInterrupt&) = delete;
  RemoveOnInterrupt(RemoveOnInterrupt&&) = delete;
  RemoveOnInterrupt& operator=(RemoveOnInterrupt&&) = delete;

 private:
  int slot_ = -1;
};

// Removes every registered path (folders with their content). Async-signal-safe; for signal
// handlers only, which exit right after it.
void remove_unfinished_writes() noexcept;

}  // namespace robocal::core
