// Staged folders and files (core/staging.hpp) and the removal of unfinished writes on an
// interruption (core/interrupt_cleanup.hpp): the target is replaced whole on commit and left
// byte for byte otherwise; nothing temporary survives a failure.
#include "robocal/core/files.hpp"
#include "robocal/core/input_error.hpp"
#include "robocal/core/interrupt_cleanup.hpp"
#include "robocal/core/staging.hpp"

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

namespace rc = robocal::core;
namespace fs = std::filesystem;

namespace {

fs::path fresh(const std::string& name) {
  fs::path dir = fs::temp_directory_path() / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::map<std::string, std::string> contents(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file())
      out[fs::relative(e.path(), dir).generic_string()] = rc::read_text_file(e.path());
  return out;
}

// Every entry of `dir` (not recursive), by name.
std::vector<std::string> names(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}

// A results folder with a file, a sub-folder and a leftover temporary.
fs::path results_in(const fs::path& dir) {
  fs::path results = dir / "results";
  rc::write_file_atomic(results / "a.json", "old a\n");
  rc::write_file_atomic(results / "stale.json", "old stale\n");
  rc::write_file_atomic(results / "cameras" / "cam0.yaml", "old camera\n");
  std::ofstream(results / "half.json.tmp") << "half";
  return results;
}

}  // namespace

TEST(StagedDirectory, CommitReplacesTheFolderWholeWithoutWhatWasLeftOut) {
  const fs::path dir = fresh("staged_commit");
  const fs::path results = results_in(dir);
  {
    rc::StagedDirectory staging(results, rc::StagedDirectory::Start::kCopyOfTarget, {"stale.json"});
    EXPECT_EQ(staging.path().filename(), "results");
    EXPECT_EQ(contents(staging.path()),
              (std::map<std::string, std::string>{{"a.json", "old a\n"},
                                                  {"cameras/cam0.yaml", "old camera\n"}}));
    rc::write_file_atomic(staging.path() / "a.json", "new a\n");
    rc::write_file_atomic(staging.path() / "b.json", "new b\n");
    EXPECT_EQ(rc::read_text_file(results / "a.json"), "old a\n") << "changed before the commit";
    staging.commit();
  }
  EXPECT_EQ(
      contents(results),
      (std::map<std::string, std::string>{
          {"a.json", "new a\n"}, {"b.json", "new b\n"}, {"cameras/cam0.yaml", "old camera\n"}}));
  EXPECT_EQ(names(dir), std::vector<std::string>{"results"});
}

TEST(StagedDirectory, WithoutACommitTheTargetIsUntouchedAndTheStagingRemoved) {
  const fs::path dir = fresh("staged_rollback");
  const fs::path results = results_in(dir);
  const auto before = contents(results);
  try {
    rc::StagedDirectory staging(results, rc::StagedDirectory::Start::kCopyOfTarget, {"a.json"});
    rc::write_file_atomic(staging.path() / "a.json", "new a\n");
    throw std::runtime_error("the stage failed");
  } catch (const std::runtime_error&) {
  }
  EXPECT_EQ(contents(results), before);
  EXPECT_EQ(names(dir), std::vector<std::string>{"results"});
}

TEST(StagedDirectory, ANewFolderAppearsOnlyOnCommit) {
  const fs::path dir = fresh("staged_new");
  const fs::path out = dir / "session";
  {
    rc::StagedDirectory staging(out, rc::StagedDirectory::Start::kEmpty);
    rc::write_file_atomic(staging.path() / "session.yaml", "x\n");
    EXPECT_FALSE(fs::exists(out));
  }
  EXPECT_FALSE(fs::exists(out));
  EXPECT_TRUE(fs::is_empty(dir));
  {
    rc::StagedDirectory staging(out, rc::StagedDirectory::Start::kEmpty);
    rc::write_file_atomic(staging.path() / "session.yaml", "x\n");
    staging.commit();
  }
  EXPECT_EQ(contents(out), (std::map<std::string, std::string>{{"session.yaml", "x\n"}}));
  EXPECT_EQ(names(dir), std::vector<std::string>{"session"});
}

// A child process stages and is killed (no handler runs): its staging folder stays until the
// next staging of the same target, which removes it; a staging of a running process stays.
TEST(StagedDirectory, TheNextStagingRemovesWhatAKilledProcessLeft) {
  const fs::path dir = fresh("staged_killed");
  const fs::path results = results_in(dir);
  const pid_t child = ::fork();
  if (child == 0) {
    const rc::StagedDirectory staging(results, rc::StagedDirectory::Start::kCopyOfTarget);
    ::pause();
    ::_exit(0);
  }
  for (int i = 0; i < 500 && names(dir).size() < 2; ++i) ::usleep(10000);
  ASSERT_EQ(names(dir).size(), 2U) << "the child's staging folder";
  {
    const rc::StagedDirectory mine(results, rc::StagedDirectory::Start::kEmpty);
    EXPECT_EQ(names(dir).size(), 3U) << "a running process's staging is left alone";
  }
  ::kill(child, SIGKILL);
  ::waitpid(child, nullptr, 0);
  EXPECT_EQ(names(dir).size(), 2U);
  { const rc::StagedDirectory next(results, rc::StagedDirectory::Start::kEmpty); }
  EXPECT_EQ(names(dir), std::vector<std::string>{"results"});
}

TEST(StagedFiles, AFolderGivenAsAFileReplacesNothing) {
  const fs::path dir = fresh("staged_files");
  rc::write_file_atomic(dir / "report.json", "old report\n");
  fs::create_directories(dir / "emptyd");
  rc::StagedFiles files;
  files.add(dir / "report.json", "new report\n");
  try {
    files.add(dir / "emptyd", "camera\n");
    FAIL() << "a folder was taken as the file";
  } catch (const rc::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("emptyd: is a folder"), std::string::npos) << e.what();
  }
  EXPECT_EQ(rc::read_text_file(dir / "report.json"), "old report\n");
  EXPECT_EQ(names(dir), (std::vector<std::string>{"emptyd", "report.json"}));
}

TEST(StagedFiles, AllFilesAreReplacedTogetherOrNone) {
  const fs::path dir = fresh("staged_files_all");
  rc::write_file_atomic(dir / "a.txt", "old a\n");
  fs::create_directories(dir / "b.txt.tmp");  // b's temporary cannot be written
  rc::StagedFiles failing;
  failing.add(dir / "a.txt", "new a\n");
  failing.add(dir / "b.txt", "new b\n");
  EXPECT_THROW(failing.commit(), rc::InputError);
  EXPECT_EQ(rc::read_text_file(dir / "a.txt"), "old a\n");
  EXPECT_EQ(names(dir), std::vector<std::string>{"a.txt"}) << "a temporary is left";
  rc::StagedFiles both;
  both.add(dir / "a.txt", "new a\n");
  both.add(dir / "b.txt", "new b\n");
  both.commit();
  EXPECT_EQ(contents(dir),
            (std::map<std::string, std::string>{{"a.txt", "new a\n"}, {"b.txt", "new b\n"}}));
}

TEST(WriteFileAtomic, AFolderAsTheFileIsRefusedAndNoTemporaryIsLeft) {
  const fs::path dir = fresh("atomic_folder");
  fs::create_directories(dir / "emptyd");
  EXPECT_THROW(rc::write_file_atomic(dir / "emptyd", "x"), rc::InputError);
  EXPECT_EQ(names(dir), std::vector<std::string>{"emptyd"});
  // A write that fails (its temporary cannot be opened) names the file and the cause.
  fs::create_directories(dir / "y.txt.tmp" / "inner");
  try {
    rc::write_file_atomic(dir / "y.txt", "x");
    FAIL() << "the write did not fail";
  } catch (const rc::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("y.txt: cannot write file (Is a directory)"),
              std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(fs::exists(dir / "y.txt"));
}

TEST(RemoveOnInterrupt, RemovesRegisteredFoldersWholeAndForgetsReleasedOnes) {
  const fs::path dir = fresh("interrupt_cleanup");
  rc::write_file_atomic(dir / "staging" / "results" / "cameras" / "cam0.yaml", "x");
  rc::write_file_atomic(dir / "staging" / "results" / "a.json", "x");
  rc::write_file_atomic(dir / "kept" / "a.json", "x");
  { const rc::RemoveOnInterrupt released(dir / "kept"); }
  const rc::RemoveOnInterrupt registered(dir / "staging");
  rc::remove_unfinished_writes();
  EXPECT_EQ(names(dir), std::vector<std::string>{"kept"});
}

TEST(StagedDirectory, AFileWhereTheFolderShouldBeIsNeverReplaced) {
  const fs::path dir = fresh("staged_file_target");
  rc::write_file_atomic(dir / "results", "not a folder\n");
  try {
    const rc::StagedDirectory staging(dir / "results", rc::StagedDirectory::Start::kCopyOfTarget);
    FAIL() << "a file was taken as the folder";
  } catch (const rc::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("results: exists and is not a folder"), std::string::npos)
        << e.what();
  }
  EXPECT_EQ(rc::read_text_file(dir / "results"), "not a folder\n");
  EXPECT_EQ(names(dir), std::vector<std::string>{"results"});
}
