#pragma once
// Where the checkout, its testdata, the shared real data and the built `robocal` are, for tests
// and benches. Force-included into every test and bench source (tests/support/CMakeLists.txt):
// the paths are compiled into one small object, so no other test object embeds an absolute path
// and ccache shares those objects between checkouts (CI's clean clone, worktrees).

namespace robocal::test {
const char* source_dir();
const char* testdata_dir();
const char* shared_data_dir();
const char* robocal_binary();
}  // namespace robocal::test

#define ROBOCAL_SOURCE_DIR (::robocal::test::source_dir())
#define ROBOCAL_TESTDATA_DIR (::robocal::test::testdata_dir())
#define ROBOCAL_SHARED_DATA_DIR (::robocal::test::shared_data_dir())
#define ROBOCAL_BINARY (::robocal::test::robocal_binary())
