// `robocal report` end to end: a small demo session (which writes its report at the end), the
// page checked as a file (size, every figure, no network reference) and rendered by headless
// Chromium (not blank, every figure in the DOM, no console errors, any network request would
// fail and show as one); and a session without identification results refused with exit code 3,
// its existing page untouched. The parameter counts on the page are identification.json's, and
// section 6 names parameters by their labels only (raw names in tooltips). A session carrying
// the wizard's held-out poses measured by the cameras (results/held_out.json) shows them, without
// the advice to validate; a record from other measurements is not shown and says why.
#include "session/results_files.hpp"
#include "session_test_support.hpp"
#include "summary/report_page.hpp"

#include <fmt/core.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>

namespace {

namespace fs = std::filesystem;
using robocal::test::copy_recorded;
using robocal::test::read_file;
using robocal::test::run_cli;

// One demo session for all checks of this file (about 20 s). ctest runs every TEST in its own
// process, in parallel: the checks are one TEST so that the demo runs once.
const fs::path& demo_session() {
  static const fs::path dir = [] {
    const auto d = fs::temp_directory_path() / "robocal_e2e_report_demo";
    fs::remove_all(d);
    const int code =
        run_cli({"demo", "--quick", "--poses", "20", "--held-out", "120", "--route", "pose",
                 "--seed", "2", "--out", d.string(), "--json",
                 (fs::temp_directory_path() / "robocal_e2e_report_demo.json").string()});
    EXPECT_EQ(code, 0);
    return d;
  }();
  return dir;
}

fs::path page_of(const fs::path& session) {
  return session / "results" / "report.html";
}

// The hosts of every http(s) URL in a text (Chromium's network log).
std::set<std::string> hosts_in(const std::string& text) {
  std::set<std::string> hosts;
  for (const std::string scheme : {"http://", "https://"})
    for (auto at = text.find(scheme); at != std::string::npos; at = text.find(scheme, at + 1)) {
      const auto begin = at + scheme.size();
      const auto end = text.find_first_of("/\\\" ;?:", begin);
      hosts.insert(text.substr(begin, end == std::string::npos ? end : end - begin));
    }
  return hosts;
}

// The visible text of the page's element with id `id` (a <div> or <p>): tags and their attributes
// (tooltips) removed.
std::string text_of(const std::string& html, const std::string& id) {
  const auto begin = html.find("id=\"" + id + "\"");
  if (begin == std::string::npos) return "";
  const auto end = html.find("</div>", begin);
  const std::string part = html.substr(begin, end == std::string::npos ? end : end - begin);
  std::string text;
  bool in_tag = true;  // starts inside the element's opening tag
  for (const char c : part) {
    if (c == '<') in_tag = true;
    if (!in_tag) text += c;
    if (c == '>') in_tag = false;
  }
  return text;
}

// The page's parameter counts are identification.json's: free = the analysis's identifiable and
// held lists, identified = the parameters estimated, held at nominal = the number identify
// writes (candidates - estimated); and section 6 shows labels, never a raw name with a label.
void check_parameter_counts_and_labels(const fs::path& session) {
  const std::string html = read_file(page_of(session));
  const auto id = nlohmann::json::parse(read_file(session / "results" / "identification.json"));
  const auto& result = id.at("result");
  std::size_t identified = 0;
  for (const auto& p : result.at("parameters")) identified += p.at("estimated").get<bool>();
  const std::size_t total = result.at("parameters").size();
  const std::size_t free = result.at("identifiability").at("identifiable").size() +
                           result.at("identifiability").at("held_at_nominal").size();
  const auto held = id.at("held_at_nominal").get<std::size_t>();
  EXPECT_EQ(held, free - identified);
  ASSERT_GT(held, 0U) << "the demo's robot holds parameters: section 6 has something to say";
  EXPECT_NE(
      html.find(fmt::format("{} of the {} free parameters were identified", identified, free)),
      std::string::npos);
  EXPECT_NE(html.find(fmt::format("{} of the {} free parameters are held at nominal", held, free)),
            std::string::npos);
  if (total > free) {
    EXPECT_NE(html.find(fmt::format("{} more are fixed in the robot file ({} parameters in all)",
                                    total - free, total)),
              std::string::npos);
  }
  // The first analysis's own count sentence ("N candidate parameters ... M held") is not shown:
  // after a relinearised solve its counts are not the result's.
  EXPECT_EQ(html.find("candidate parameters"), std::string::npos);
  // The parameter table lists exactly the identified ones.
  const auto table = html.substr(html.find("id=\"fig-parameters\""));
  std::size_t rows = 0;
  for (auto at = table.find("<tr><td"); at < table.find("</table>");
       at = table.find("<tr><td", at + 1))
    ++rows;
  EXPECT_EQ(rows, identified);

  // Section 6: no raw name of a labelled parameter in its text, but each named parameter's raw
  // name at hand as a tooltip.
  const std::string text = text_of(html, "fig-not-identified");
  ASSERT_FALSE(text.empty());
  EXPECT_FALSE(std::regex_search(text, std::regex(R"(body[0-9]+\.)"))) << text;
  std::size_t labelled = 0;
  for (const auto& p : result.at("parameters")) {
    const auto name = p.at("name").get<std::string>();
    if (p.value("label", name) == name) continue;
    ++labelled;
    EXPECT_FALSE(std::regex_search(
        text,
        std::regex("(^|[^A-Za-z0-9_.])" + std::regex_replace(name, std::regex(R"(\.)"), R"(\.)") +
                   "([^A-Za-z0-9_]|$)")))
        << name << " in: " << text;
  }
  EXPECT_GT(labelled, 0U);
  const auto section = html.substr(html.find("id=\"fig-not-identified\""));
  EXPECT_NE(section.find("<span class=\"param\" title=\"body"), std::string::npos);
  const auto summary = nlohmann::json::parse(
      read_file(fs::temp_directory_path() / "robocal_e2e_report_demo.json"))["report"];
  EXPECT_EQ(summary["parameters"]["free"], free);
  EXPECT_EQ(summary["parameters"]["identified"], identified);
  EXPECT_EQ(summary["parameters"]["held_at_nominal"], held);
  EXPECT_EQ(summary["estimated_parameters"], identified);
}

void check_demo_page() {
  const fs::path page = page_of(demo_session());
  ASSERT_TRUE(fs::exists(page));
  const std::string html = read_file(page);
  EXPECT_LE(html.size(), 2U * 1024U * 1024U);
  for (const auto& id : robocal::app::report_figure_ids())
    EXPECT_NE(html.find("id=\"" + id + "\""), std::string::npos) << id;
  // Nothing the browser could fetch: no URLs, no src/href, no CSS url(), no scripts.
  for (const char* banned : {"http:", "https:", "src=", "href=", "url(", "<script", "@import"})
    EXPECT_EQ(html.find(banned), std::string::npos) << banned;
  // The held-out figures are there (validated session), and the JSON summary agrees.
  EXPECT_NE(html.find("inside the measured region"), std::string::npos);
  EXPECT_NE(html.find("outside the measured region"), std::string::npos);
  std::ifstream in(fs::temp_directory_path() / "robocal_e2e_report_demo.json");
  const auto demo = nlohmann::json::parse(in);
  EXPECT_EQ(demo["report"]["status"], "ok");
  EXPECT_EQ(demo["report"]["held_out_poses"], demo["validate"]["held_out_poses"]);
  EXPECT_EQ(demo["report"]["calibrated_rms_m"], demo["validate"]["calibrated"]["rms_m"]);
  // Validated against the truth, labelled so; no advice to validate.
  EXPECT_NE(html.find("held-out poses, against the truth"), std::string::npos);
  EXPECT_EQ(html.find("no held-out validation"), std::string::npos);
  EXPECT_EQ(html.find("robocal wizard --resume"), std::string::npos);
  check_parameter_counts_and_labels(demo_session());
}

void check_in_chromium() {
  const char* candidates[] = {"/usr/bin/chromium", "/usr/bin/chromium-browser"};
  std::string chromium;
  for (const char* c : candidates)
    if (fs::exists(c)) chromium = c;
  if (chromium.empty())
    GTEST_SKIP() << "chromium is not installed (Debian package `chromium`, scripts/bootstrap.sh): "
                    "the page is not rendered by a browser in this run";
  const fs::path page = fs::absolute(page_of(demo_session()));
  const fs::path out = fs::temp_directory_path() / "robocal_e2e_report_chromium";
  fs::remove_all(out);
  fs::create_directories(out);
  // Every host resolves to nothing (nothing leaves the machine); the network log records every
  // request the browser made all the same.
  const auto run = [&](const std::string& what, const std::string& url, const std::string& args) {
    const std::string command =
        "timeout 120 " + chromium +
        " --headless --no-sandbox --disable-gpu --no-first-run --disable-extensions"
        " --disable-background-networking --disable-component-update --disable-sync"
        " '--host-resolver-rules=MAP * ~NOTFOUND' --user-data-dir=" +
        (out / ("profile-" + what)).string() +
        " --log-net-log=" + (out / (what + ".netlog.json")).string() +
        " --enable-logging=stderr --v=0 --window-size=1100,3000 " + args + " " + url + " >" +
        (out / (what + ".out")).string() + " 2>" + (out / (what + ".log")).string();
    return std::system(command.c_str());
  };
  const std::string shot = (out / "page.png").string();
  ASSERT_EQ(run("shot", "file://" + page.string(), "--screenshot=" + shot), 0)
      << read_file(out / "shot.log");
  ASSERT_EQ(run("dom", "file://" + page.string(), "--dump-dom"), 0) << read_file(out / "dom.log");
  // Chromium contacts its own services (update checks, accounts) whatever it shows: the same
  // browser on an empty page is the baseline the report's requests are measured against.
  ASSERT_EQ(run("blank", "about:blank", "--dump-dom"), 0) << read_file(out / "blank.log");

  // Not blank: a good share of the screenshot is drawn, including the calibrated model's blue.
  const cv::Mat image = cv::imread(shot, cv::IMREAD_COLOR);
  ASSERT_FALSE(image.empty()) << shot;
  std::size_t drawn = 0, blue = 0;
  for (int r = 0; r < image.rows; ++r)
    for (int c = 0; c < image.cols; ++c) {
      const auto& p = image.at<cv::Vec3b>(r, c);  // BGR
      if (p[0] < 235 || p[1] < 235 || p[2] < 235) ++drawn;
      if (std::abs(p[0] - 0xb2) < 12 && std::abs(p[1] - 0x6f) < 12 && std::abs(p[2] - 0x1f) < 12)
        ++blue;
    }
  const double total = static_cast<double>(image.rows) * image.cols;
  EXPECT_GT(static_cast<double>(drawn) / total, 0.03) << shot;
  EXPECT_GT(blue, 200U) << shot;

  // Every figure in the rendered DOM.
  const std::string dom = read_file(out / "dom.out");
  for (const auto& id : robocal::app::report_figure_ids())
    EXPECT_NE(dom.find("id=\"" + id + "\""), std::string::npos) << id;
  // No console message at all: the page has no scripts, so anything there is the browser
  // reporting a problem with the page (Chromium logs console.error as INFO:CONSOLE too).
  for (const auto* log : {"shot.log", "dom.log"}) {
    std::istringstream lines(read_file(out / log));
    for (std::string line; std::getline(lines, line);)
      EXPECT_EQ(line.find("CONSOLE"), std::string::npos) << log << ": " << line;
  }
  // No request to any host the browser does not contact on an empty page.
  const auto blank_hosts = hosts_in(read_file(out / "blank.netlog.json"));
  for (const auto* netlog : {"shot.netlog.json", "dom.netlog.json"})
    for (const auto& host : hosts_in(read_file(out / netlog)))
      EXPECT_TRUE(blank_hosts.count(host) > 0) << netlog << ": the page requested " << host;

  // The checks can fail: the same page with an external image and a console error is caught.
  std::string bad = read_file(page);
  bad.insert(bad.find("<body>") + 6,
             "<img src=\"https://example.com/x.png\"><script>console.error('x')</script>");
  { std::ofstream(out / "bad.html") << bad; }
  ASSERT_EQ(run("bad", "file://" + (out / "bad.html").string(), "--dump-dom"), 0);
  const auto bad_hosts = hosts_in(read_file(out / "bad.netlog.json"));
  EXPECT_TRUE(bad_hosts.count("example.com") > 0 && blank_hosts.count("example.com") == 0);
  EXPECT_NE(read_file(out / "bad.log").find("CONSOLE"), std::string::npos);
}

void check_without_identification() {
  const fs::path bare = fs::temp_directory_path() / "robocal_e2e_report_bare";
  copy_recorded(demo_session(), bare);
  fs::create_directories(bare / "results");
  const std::string old_page = "<html>an earlier report</html>\n";
  { std::ofstream(page_of(bare)) << old_page; }
  testing::internal::CaptureStderr();
  const int code = run_cli({"report", bare.string()});
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(code, 3);
  EXPECT_NE(err.find("identification.json"), std::string::npos) << err;
  EXPECT_NE(err.find("robocal identify"), std::string::npos) << err;
  EXPECT_EQ(read_file(page_of(bare)), old_page);
}

void check_without_truth() {
  // The demo session's results without validation.json: the fit on the measured poses, said so.
  const fs::path recorded = fs::temp_directory_path() / "robocal_e2e_report_recorded";
  fs::remove_all(recorded);
  fs::copy(demo_session(), recorded, fs::copy_options::recursive);
  fs::remove(recorded / "results" / "validation.json");
  fs::remove(recorded / "results" / "report.html");
  ASSERT_EQ(run_cli({"report", recorded.string()}), 0);
  const std::string html = read_file(page_of(recorded));
  EXPECT_NE(html.find("no held-out validation"), std::string::npos);
  // The advice names what records a held-out validation in the session; `robocal identify
  // --holdout-every` does not (it applies to measurements files, and writes no session result).
  EXPECT_NE(html.find("robocal wizard --resume"), std::string::npos);
  EXPECT_EQ(html.find("--holdout-every"), std::string::npos);
  for (const auto& id : robocal::app::report_figure_ids())
    EXPECT_NE(html.find("id=\"" + id + "\""), std::string::npos) << id;
}

// A session whose held-out poses were measured by the cameras (the wizard's validation step
// writes results/held_out.json; here written through the same writer for every 4th of the demo's
// measured poses, with errors of known size): the page shows them as the accuracy, labelled as
// measured by the cameras, with no advice to validate; the JSON summary agrees. A record whose
// pose was measured elsewhere than the session's measurement now is not shown, and the page says
// why and gives the advice again.
void check_held_out_measured() {
  const fs::path dir = fs::temp_directory_path() / "robocal_e2e_report_held_out";
  fs::remove_all(dir);
  fs::copy(demo_session(), dir, fs::copy_options::recursive);
  fs::remove(dir / "results" / "validation.json");  // a real cell has no truth
  const robocal::app::ResultsLayout results{dir};
  const auto used = robocal::app::read_used_measured_poses(results, "");
  robocal::app::HeldOutRecord record;
  record.every = 4;
  for (std::size_t k = 0; k < used.size(); ++k) {
    if ((k + 1) % 4 != 0) continue;
    const Eigen::Vector3d measured = used[k].rig_T_target.translation();
    // 6 µm and 1.5 mm along alternating directions: RMS and worst exactly these.
    const Eigen::Vector3d dir_k = k % 8 == 3 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitZ();
    record.poses.push_back({used[k].pose, measured, 1.5e-3 * dir_k, -6e-6 * dir_k});
  }
  record.fit_poses = used.size() - record.poses.size();
  ASSERT_GE(record.poses.size(), 3U);
  robocal::app::write_held_out(results, record);
  const fs::path json = dir / "report.json";
  ASSERT_EQ(run_cli({"report", dir.string(), "--json", json.string()}), 0);
  const std::string html = read_file(page_of(dir));
  EXPECT_NE(html.find("held-out poses, measured by the cameras"), std::string::npos);
  EXPECT_NE(html.find(fmt::format("Calibration brought the tool's position error on {} measured "
                                  "poses the fit never saw from 1.50 mm to 6.0 µm RMS (worst "
                                  "6.0 µm), as the cameras measured them.",
                                  record.poses.size())),
            std::string::npos);
  EXPECT_NE(html.find(fmt::format("every 4th of the measured poses was left out of a second "
                                  "identification, made the same way from the other {}",
                                  record.fit_poses)),
            std::string::npos);
  EXPECT_NE(html.find("Error of each of the " + std::to_string(record.poses.size()) +
                      " held-out poses (measured by the cameras)"),
            std::string::npos);
  EXPECT_EQ(html.find("no held-out validation"), std::string::npos);
  EXPECT_EQ(html.find("robocal wizard --resume"), std::string::npos);
  EXPECT_EQ(html.find("against the truth"), std::string::npos);
  const auto summary = nlohmann::json::parse(read_file(json));
  EXPECT_EQ(summary["held_out_measured"]["poses"], record.poses.size());
  EXPECT_NEAR(summary["held_out_measured"]["calibrated_rms_m"].get<double>(), 6e-6, 1e-12);
  EXPECT_NEAR(summary["held_out_measured"]["nominal_rms_m"].get<double>(), 1.5e-3, 1e-12);
  EXPECT_NEAR(summary["calibrated_rms_m"].get<double>(), 6e-6, 1e-12);

  // The session measured again (here: one held-out pose's board 1 mm elsewhere in the record).
  record.poses[1].measured.x() += 1e-3;
  robocal::app::write_held_out(results, record);
  ASSERT_EQ(run_cli({"report", dir.string(), "--json", json.string()}), 0);
  const std::string stale = read_file(page_of(dir));
  EXPECT_EQ(stale.find("held-out poses, measured by the cameras"), std::string::npos);
  EXPECT_NE(stale.find("The held-out poses of results/held_out.json are not shown: its held-out "
                       "pose " +
                       record.poses[1].pose + " has been measured again since."),
            std::string::npos);
  EXPECT_NE(stale.find("no held-out validation"), std::string::npos);
  EXPECT_NE(stale.find("robocal wizard --resume"), std::string::npos);
  EXPECT_TRUE(nlohmann::json::parse(read_file(json))["held_out_measured"].contains("not_shown"));
}

// Held-out configurations a model could not answer are failures the page names, with the
// count (edited into the demo's validation.json: the demo itself has none); a validation.json
// from before per-pose points were written is refused with what to run, the old page kept.
void check_unanswered_and_old_validation() {
  const fs::path edited = fs::temp_directory_path() / "robocal_e2e_report_unanswered";
  fs::remove_all(edited);
  fs::copy(demo_session(), edited, fs::copy_options::recursive);
  const fs::path validation = edited / "results" / "validation.json";
  nlohmann::json v = nlohmann::json::parse(read_file(validation));
  const auto answered = v.at("held_out_points").at("position_m").size();
  v["unanswered"] = {{"nominal", 0}, {"calibrated", 7}};
  v["held_out_drawn"] = answered + 7;
  { std::ofstream(validation) << v.dump(); }
  ASSERT_EQ(run_cli({"report", edited.string()}), 0);
  const std::string html = read_file(page_of(edited));
  EXPECT_NE(html.find("FAILURES: of " + std::to_string(answered + 7)), std::string::npos);
  EXPECT_NE(html.find("calibrated model 7"), std::string::npos);

  v.erase("held_out_points");
  { std::ofstream(validation) << v.dump(); }
  const std::string old_page = read_file(page_of(edited));
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"report", edited.string()}), 3);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("robocal validate"), std::string::npos) << err;
  EXPECT_EQ(read_file(page_of(edited)), old_page);
}

TEST(Report, DemoPageBadInputAndHeadlessChromium) {
  {
    SCOPED_TRACE("the demo's page");
    check_demo_page();
  }
  {
    SCOPED_TRACE("a session without identification results");
    check_without_identification();
  }
  {
    SCOPED_TRACE("a session without truth");
    check_without_truth();
  }
  {
    SCOPED_TRACE("held-out poses measured by the cameras");
    check_held_out_measured();
  }
  {
    SCOPED_TRACE("unanswered held-out configurations; an old validation.json");
    check_unanswered_and_old_validation();
  }
  SCOPED_TRACE("headless Chromium");
  check_in_chromium();  // last: skips the test when chromium is absent
}

}  // namespace
