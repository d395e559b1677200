#pragma once
// Helpers of the session tests: run the CLI in-process, fingerprint recorded data, copy a
// session's recorded data without its results.
#include "cli/command_registry.hpp"
#include "session/session.hpp"

#include "robocal/core/files.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

namespace robocal::test {

inline int run_cli(const std::vector<std::string>& args) {
  std::vector<const char*> argv = {"robocal"};
  for (const auto& a : args) argv.push_back(a.c_str());
  return robocal::app::run_cli(static_cast<int>(argv.size()), argv.data());
}

// A results file's JSON (a test failure when it cannot be opened).
inline nlohmann::json load_json(const std::filesystem::path& p) {
  std::ifstream in(p);
  EXPECT_TRUE(in) << p;
  return nlohmann::json::parse(in);
}

// FNV-1a of every file's relative path and bytes, outside results/: the recorded data.
inline std::map<std::string, std::uint64_t> recorded_fingerprint(
    const std::filesystem::path& session) {
  std::map<std::string, std::uint64_t> out;
  for (const auto& e : std::filesystem::recursive_directory_iterator(session)) {
    if (!e.is_regular_file()) continue;
    const std::string rel = std::filesystem::relative(e.path(), session).generic_string();
    if (rel.rfind("results/", 0) == 0) continue;
    const std::string bytes = robocal::core::read_text_file(e.path());
    std::uint64_t h = 1469598103934665603ULL;
    for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ULL;
    out[rel] = h;
  }
  return out;
}

// Copies a session's recorded data (everything but results/) to `to`.
inline void copy_recorded(const std::filesystem::path& from, const std::filesystem::path& to) {
  namespace fs = std::filesystem;
  fs::remove_all(to);
  fs::create_directories(to);
  for (const auto& e : fs::directory_iterator(from)) {
    if (e.path().filename() == "results") continue;
    fs::copy(e.path(), to / e.path().filename(), fs::copy_options::recursive);
  }
}

inline std::string read_file(const std::filesystem::path& p) {
  return robocal::core::read_text_file(p);
}

}  // namespace robocal::test
