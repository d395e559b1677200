#include "session/results_transaction.hpp"

#include "robocal/core/input_error.hpp"

namespace robocal::app {

namespace fs = std::filesystem;

ResultsTransaction::ResultsTransaction(const fs::path& session,
                                       std::initializer_list<fs::path> stale)
    : staging_(ResultsLayout{session}.dir(), core::StagedDirectory::Start::kCopyOfTarget),
      staged_{staging_.root()} {
  const fs::path results = ResultsLayout{session}.dir();
  for (const fs::path& file : stale) {
    const fs::path in_staging = staged_.dir() / fs::relative(file, results);
    std::error_code ec;
    fs::remove_all(in_staging, ec);
    if (ec)
      throw core::InputError(in_staging.string() + ": cannot remove from the staging folder (" +
                             ec.message() + ")");
  }
}

}  // namespace robocal::app
