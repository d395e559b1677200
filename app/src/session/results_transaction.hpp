#pragma once
// A stage's results as a transaction (core/staging.hpp). The stage writes through staged(): a
// copy of the session's results/ in a staging folder beside it, from which the stage first
// discards what its new results make stale. commit() replaces results/ with the copy in one step.
// A stage commits when it reaches its verdict on the session's data: ok, or refused by a
// plausibility gate (the refusal is recorded in its report, which the next stage and the report
// page read). It does not commit when it cannot finish (a bad input file, a write that fails, a
// step that failed, an interruption): results/ stays exactly as it was, and the staging folder
// is removed (on an interruption by the signal handler; after a kill, by the next stage).
#include "session/results_layout.hpp"

#include "robocal/core/staging.hpp"

#include <filesystem>
#include <initializer_list>

namespace robocal::app {

class ResultsTransaction {
 public:
  // Stages a copy of `session`'s results/ without the files `stale` (absolute paths from
  // ResultsLayout{session}; a folder is discarded whole). Throws InputError naming the folder
  // when the staging folder cannot be made.
  ResultsTransaction(const std::filesystem::path& session,
                     std::initializer_list<std::filesystem::path> stale);

  // Where the stage writes (and reads back) its results: ResultsLayout over the staging folder.
  [[nodiscard]] const ResultsLayout& staged() const { return staged_; }

  // Replaces the session's results/ with the staged copy in one step.
  void commit() { staging_.commit(); }

 private:
  core::StagedDirectory staging_;
  ResultsLayout staged_;
};

}  // namespace robocal::app
