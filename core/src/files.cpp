#include "robocal/core/files.hpp"

#include "robocal/core/input_error.hpp"
#include "robocal/core/interrupt_cleanup.hpp"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

namespace robocal::core {

namespace fs = std::filesystem;

std::string read_text_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string() + ": cannot open file (" + std::strerror(errno) + ")");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void write_file_atomic(const fs::path& path, const std::string& bytes, Overwrite overwrite) {
  std::error_code ec;
  if (overwrite == Overwrite::kRefuse && fs::exists(path, ec))
    throw InputError(path.string() + ": exists; recorded data is never overwritten");
  if (fs::is_directory(path, ec))
    throw InputError(path.string() + ": is a folder; give the name of the file to write");
  if (path.has_parent_path()) fs::create_directories(path.parent_path(), ec);
  fs::path tmp = path;
  tmp += ".tmp";
  // The temporary never outlives a failed write: removed on an error here, and by the signal
  // handler on an interruption.
  const RemoveOnInterrupt cleanup(tmp);
  const auto fail = [&tmp](const std::string& what) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw InputError(what);
  };
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    // errno says why ("Permission denied", "No space left on device"): the operator can act on it.
    if (!out) fail(path.string() + ": cannot write file (" + std::strerror(errno) + ")");
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out.flush()) fail(path.string() + ": write failed (" + std::strerror(errno) + ")");
  }
  fs::rename(tmp, path, ec);
  if (ec) fail(path.string() + ": cannot rename temporary file: " + ec.message());
}

}  // namespace robocal::core
