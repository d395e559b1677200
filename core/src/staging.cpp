#include "robocal/core/staging.hpp"

#include "robocal/core/input_error.hpp"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>

namespace robocal::core {

namespace fs = std::filesystem;

namespace {

// Staging folders of one process are told apart by a counter (batch stages several sessions at
// once).
std::atomic<unsigned> staging_counter{0};

std::string staging_prefix(const fs::path& target) {
  // Appended piece by piece: GCC 12 warns (-Wrestrict, a false positive) on "." + std::string.
  std::string prefix(1, '.');
  prefix.append(target.filename().string()).append(".staging-");
  return prefix;
}

// Removes the staging folders of `target` whose process is gone (killed before it could remove
// them). A folder of a running process (this one's other stagings included) is left alone.
void remove_abandoned_stagings(const fs::path& target) {
  const fs::path parent = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  const std::string prefix = staging_prefix(target);
  std::error_code ec;
  std::vector<fs::path> abandoned;
  for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    const long pid = std::strtol(name.c_str() + prefix.size(), nullptr, 10);
    if (pid <= 0) continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;
    abandoned.push_back(it->path());
  }
  for (const fs::path& p : abandoned) fs::remove_all(p, ec);
}

// Copies `from` into `to` (created), without "*.tmp" files and without `leave_out` (relative
// paths; a folder with its content).
void copy_folder(const fs::path& from, const fs::path& to, const std::vector<fs::path>& leave_out,
                 std::error_code& ec) {
  fs::create_directories(to, ec);
  for (fs::recursive_directory_iterator it(from, ec), end; !ec && it != end; it.increment(ec)) {
    const fs::path rel = it->path().lexically_relative(from);
    bool left_out = false;
    for (const fs::path& l : leave_out) left_out = left_out || rel == l.lexically_normal();
    if (left_out || it->path().extension() == ".tmp") {
      if (it->is_directory(ec)) it.disable_recursion_pending();
      continue;
    }
    if (it->is_symlink(ec))
      fs::copy_symlink(it->path(), to / rel, ec);
    else if (it->is_directory(ec))
      fs::create_directories(to / rel, ec);
    else
      fs::copy_file(it->path(), to / rel, ec);
  }
}

}  // namespace

StagedDirectory::StagedDirectory(fs::path target, Start start,
                                 const std::vector<fs::path>& leave_out)
    : target_(std::move(target)) {
  std::error_code ec;
  // Whatever stands at the target that is not a folder is not ours to replace.
  if (fs::exists(fs::symlink_status(target_, ec)) && !fs::is_directory(target_, ec))
    throw InputError(target_.string() +
                     ": exists and is not a folder; move it away (it is never replaced)");
  remove_abandoned_stagings(target_);
  const fs::path parent = target_.parent_path().empty() ? fs::path(".") : target_.parent_path();
  std::string name = staging_prefix(target_);
  name.append(std::to_string(::getpid())).append("-");
  name.append(std::to_string(staging_counter.fetch_add(1)));
  root_ = parent / name;
  staged_ = root_ / target_.filename();
  cleanup_ = std::make_unique<RemoveOnInterrupt>(root_);
  if (start == Start::kCopyOfTarget && fs::is_directory(target_, ec)) {
    copy_folder(target_, staged_, leave_out, ec);
    if (ec) {
      const std::string why = ec.message();
      fs::remove_all(root_, ec);
      throw InputError(target_.string() + ": cannot copy into the staging folder " +
                       root_.string() + " (" + why + ")");
    }
  } else {
    fs::create_directories(staged_, ec);
    if (ec) {
      const std::string why = ec.message();
      fs::remove_all(root_, ec);
      throw InputError(staged_.string() + ": cannot create the staging folder (" + why + ")");
    }
  }
}

StagedDirectory::~StagedDirectory() {
  std::error_code ec;
  fs::remove_all(root_, ec);
}

void StagedDirectory::commit() {
  std::error_code ec;
  const bool replace = fs::exists(target_, ec);
  int failed = 0;
  if (!replace) {
    failed = ::rename(staged_.c_str(), target_.c_str()) == 0 ? 0 : errno;
  } else if (::renameat2(AT_FDCWD, staged_.c_str(), AT_FDCWD, target_.c_str(), RENAME_EXCHANGE) !=
             0) {
    failed = errno;
    if (failed == EINVAL || failed == ENOSYS || failed == ENOTSUP) {
      // A file system without the exchange: the old folder aside, the new one in its place.
      const fs::path old = root_ / ".previous";
      failed = ::rename(target_.c_str(), old.c_str()) == 0 ? 0 : errno;
      if (failed == 0 && ::rename(staged_.c_str(), target_.c_str()) != 0) {
        failed = errno;
        ::rename(old.c_str(), target_.c_str());
      }
    }
  }
  if (failed != 0)
    throw InputError(target_.string() + ": cannot be replaced with the new results in " +
                     staged_.string() + " (" + std::strerror(failed) +
                     "); the previous results are unchanged");
  committed_ = true;
  fs::remove_all(root_, ec);  // the previous content, exchanged into the staging folder
  cleanup_.reset();
}

void StagedFiles::add(const fs::path& path, std::string bytes) {
  std::error_code ec;
  if (fs::is_directory(path, ec))
    throw InputError(path.string() + ": is a folder; give the name of the file to write");
  files_.emplace_back(path, std::move(bytes));
}

void StagedFiles::commit() {
  std::vector<fs::path> written;
  std::vector<std::unique_ptr<RemoveOnInterrupt>> cleanup;
  const auto discard = [&written] {
    std::error_code ec;
    for (const fs::path& p : written) fs::remove(p, ec);
  };
  for (const auto& [path, bytes] : files_) {
    std::error_code ec;
    if (path.has_parent_path()) fs::create_directories(path.parent_path(), ec);
    fs::path tmp = path;
    tmp += ".tmp";
    cleanup.push_back(std::make_unique<RemoveOnInterrupt>(tmp));
    written.push_back(tmp);
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) {
      const std::string why = std::strerror(errno);
      discard();
      throw InputError(path.string() + ": cannot write file (" + why + "); no file was replaced");
    }
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out.flush()) {
      const std::string why = std::strerror(errno);
      out.close();
      discard();
      throw InputError(path.string() + ": write failed (" + why + "); no file was replaced");
    }
  }
  for (std::size_t i = 0; i < files_.size(); ++i) {
    std::error_code ec;
    fs::rename(written[i], files_[i].first, ec);
    if (ec) {
      const std::string why = ec.message();
      for (std::size_t j = i; j < written.size(); ++j) fs::remove(written[j], ec);
      throw InputError(files_[i].first.string() + ": cannot rename the temporary file (" + why +
                       ")" + (i == 0 ? "; no file was replaced" : "; the files before it were"));
    }
  }
}

}  // namespace robocal::core
