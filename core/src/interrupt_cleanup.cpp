#include "robocal/core/interrupt_cleanup.hpp"

#include <fcntl.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace robocal::core {

namespace {

// A slot is free (0), being filled (1) or holds a path to remove (2). The handler reads only
// slots in state 2, whose path is complete.
struct Slot {
  std::atomic<int> state{0};
  std::array<char, 4096> path{};
};
std::array<Slot, 64> slots;

// getdents64's record (linux/dirent.h; glibc names the call only from 2.30 on).
struct LinuxDirent64 {
  std::uint64_t d_ino;
  std::int64_t d_off;
  unsigned short d_reclen;
  unsigned char d_type;
  char d_name[1];  // NOLINT(modernize-avoid-c-arrays): the kernel's flexible name field
};

bool is_dot(const char* name) {
  return name[0] == '.' && (name[1] == '\0' || (name[1] == '.' && name[2] == '\0'));
}

// Removes `name` under `dir_fd`: a file, or a folder with everything in it. System calls only.
// A writer on another thread may still add files while this runs; each folder is read again
// until it is empty (a few passes) before it is removed.
void remove_at(int dir_fd, const char* name, int depth) {
  if (::unlinkat(dir_fd, name, 0) == 0 || errno == ENOENT) return;
  if (depth > 16) return;
  for (int pass = 0; pass < 8; ++pass) {
    const int fd = ::openat(dir_fd, name, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0) return;
    alignas(LinuxDirent64) std::array<char, 2048> buffer{};
    for (;;) {
      const long n = ::syscall(SYS_getdents64, fd, buffer.data(), buffer.size());
      if (n <= 0) break;
      for (long at = 0; at < n;) {
        const auto* entry = reinterpret_cast<const LinuxDirent64*>(buffer.data() + at);
        if (!is_dot(entry->d_name)) remove_at(fd, entry->d_name, depth + 1);
        at += entry->d_reclen;
      }
    }
    ::close(fd);
    if (::unlinkat(dir_fd, name, AT_REMOVEDIR) == 0 || errno == ENOENT) return;
  }
}

}  // namespace

RemoveOnInterrupt::RemoveOnInterrupt(const std::filesystem::path& path) {
  std::error_code ec;
  const std::string absolute = std::filesystem::absolute(path, ec).string();
  if (ec || absolute.size() >= slots[0].path.size()) return;
  for (std::size_t i = 0; i < slots.size(); ++i) {
    int free = 0;
    if (!slots[i].state.compare_exchange_strong(free, 1)) continue;
    std::memcpy(slots[i].path.data(), absolute.c_str(), absolute.size() + 1);
    slots[i].state.store(2);
    slot_ = static_cast<int>(i);
    return;
  }
}

RemoveOnInterrupt::~RemoveOnInterrupt() {
  if (slot_ >= 0) slots[static_cast<std::size_t>(slot_)].state.store(0);
}

void remove_unfinished_writes() noexcept {
  const int saved = errno;
  for (Slot& slot : slots)
    if (slot.state.load() == 2) remove_at(AT_FDCWD, slot.path.data(), 0);
  errno = saved;
}

}  // namespace robocal::core
