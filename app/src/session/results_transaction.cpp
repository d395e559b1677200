#include "session/results_transaction.hpp"

#include <vector>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

std::vector<fs::path> relative_to_results(const fs::path& session,
                                          std::initializer_list<fs::path> files) {
  const fs::path results = ResultsLayout{session}.dir();
  std::vector<fs::path> out;
  out.reserve(files.size());
  for (const fs::path& f : files) out.push_back(f.lexically_relative(results));
  return out;
}

}  // namespace

ResultsTransaction::ResultsTransaction(const fs::path& session,
                                       std::initializer_list<fs::path> stale)
    : staging_(ResultsLayout{session}.dir(), core::StagedDirectory::Start::kCopyOfTarget,
               relative_to_results(session, stale)),
      staged_{staging_.root()} {}

}  // namespace robocal::app
