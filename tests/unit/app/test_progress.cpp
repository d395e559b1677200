#include "cli/progress.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <string>

namespace {

std::string read_all(std::FILE* f) {
  std::rewind(f);
  std::string text;
  char buf[256];
  while (std::fgets(buf, sizeof buf, f) != nullptr) text += buf;
  return text;
}

// In a log file (not a terminal) the bar prints one line per 10 % and a closing line, so a CI log
// of a 1000-step job stays ~11 lines long.
TEST(ProgressBar, LogOutputIsOneLinePerDecile) {
  std::FILE* log = std::tmpfile();
  ASSERT_NE(log, nullptr);
  {
    robocal::app::ProgressBar bar("render", 1000, log);
    for (int i = 0; i < 1000; ++i) bar.advance();
    bar.finish("ok");
  }
  const std::string text = read_all(log);
  std::fclose(log);
  int lines = 0;
  for (char c : text) lines += c == '\n';
  EXPECT_EQ(lines, 10) << text;  // 10 %, 20 %, ... 90 % and the closing line
  EXPECT_NE(text.find("render: 1000/1000 done"), std::string::npos) << text;
  EXPECT_NE(text.find("ok"), std::string::npos);
  EXPECT_EQ(text.find('\r'), std::string::npos) << "no terminal control codes in logs";
}

TEST(StageClock, SumsStages) {
  robocal::app::StageClock clock;
  clock.start("a");
  clock.start("b");  // starting a stage stops the previous one
  clock.stop();
  ASSERT_EQ(clock.stages().size(), 2u);
  EXPECT_GE(clock.total_seconds(), 0.0);
  EXPECT_NE(clock.table().find("total"), std::string::npos);
}

}  // namespace
