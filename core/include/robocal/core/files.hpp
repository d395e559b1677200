#pragma once
// Reading and writing whole files. Every write goes to "<path>.tmp" first and is renamed over
// the target, so a reader (or a crash) never sees half a file.
#include <filesystem>
#include <string>

namespace robocal::core {

// The whole file as bytes. Throws InputError("<path>: cannot open file").
std::string read_text_file(const std::filesystem::path& path);

enum class Overwrite {
  kReplace,  // results: replaced atomically
  kRefuse,   // recorded data: an existing file is never overwritten (InputError)
};

// Writes `bytes` atomically, creating missing parent folders. Throws InputError naming the file
// when it exists and `overwrite` is kRefuse, or when it cannot be written.
void write_file_atomic(const std::filesystem::path& path, const std::string& bytes,
                       Overwrite overwrite = Overwrite::kReplace);

}  // namespace robocal::core
