#include "batch/batch_shard.hpp"

#include "batch/batch_summary.hpp"
#include "cli/cli_common.hpp"

#include "robocal/core/files.hpp"

#include <fmt/core.h>
#include <fmt/format.h>

#include <algorithm>
#include <map>
#include <numeric>
#include <stdexcept>
#include <string_view>

namespace robocal::app {

namespace {

// Written into every shard summary; a merge refuses summaries split by another rule.
constexpr const char* kRule = "sorted-position-mod-count";

// A whole number of at most 6 digits (no sign, no spaces).
bool whole_number(std::string_view s, int& value) {
  if (s.empty() || s.size() > 6) return false;
  value = 0;
  for (const char c : s) {
    if (c < '0' || c > '9') return false;
    value = value * 10 + (c - '0');
  }
  return true;
}

[[noreturn]] void refuse(const std::string& path, const std::string& problem) {
  throw InputError(fmt::format("{}: {}", path, problem));
}

const nlohmann::json& field(const nlohmann::json& obj, const char* key, const std::string& path,
                            const char* where) {
  if (!obj.is_object() || !obj.contains(key))
    refuse(path, fmt::format("malformed batch summary: no \"{}\" in {}", key, where));
  return obj[key];
}

int int_field(const nlohmann::json& obj, const char* key, const std::string& path,
              const char* where) {
  const auto& v = field(obj, key, path, where);
  if (!v.is_number_integer())
    refuse(path, fmt::format("malformed batch summary: \"{}\" in {} is not a whole number (got {})",
                             key, where, v.dump()));
  return v.get<int>();
}

std::vector<std::string> string_list(const nlohmann::json& obj, const char* key,
                                     const std::string& path, const char* where) {
  const auto& v = field(obj, key, path, where);
  if (!v.is_array())
    refuse(path, fmt::format("malformed batch summary: \"{}\" in {} is not a list", key, where));
  std::vector<std::string> out;
  for (const auto& e : v) {
    if (!e.is_string())
      refuse(path, fmt::format("malformed batch summary: \"{}\" in {} holds {}, not a folder name",
                               key, where, e.dump()));
    out.push_back(e.get<std::string>());
  }
  return out;
}

std::string shard_name(Shard s) {
  return fmt::format("{}/{}", s.index, s.count);
}

// One summary, checked on its own: what it says about its shard, and that its sessions are that
// shard's slice of its folder list.
struct CheckedShard {
  const ShardSummary* summary = nullptr;
  Shard shard;
  std::vector<std::string> folders;  // the whole list, as given to this shard
  std::vector<nlohmann::json> rows;
};

CheckedShard check_shard_summary(const ShardSummary& s) {
  const std::string& path = s.path;
  const auto& doc = s.doc;
  if (!doc.is_object() || !doc.contains("sessions"))
    refuse(path,
           "not a batch summary (no \"sessions\"): batch-merge takes the --json files of "
           "`robocal batch --shard K/N` runs");
  if (!doc.contains("shard"))
    refuse(path,
           "the summary of a batch without --shard (no \"shard\" section): batch-merge takes "
           "the --json files of `robocal batch --shard K/N` runs");
  const auto& sec = doc["shard"];
  CheckedShard c;
  c.summary = &s;
  c.shard.index = int_field(sec, "index", path, "\"shard\"");
  c.shard.count = int_field(sec, "count", path, "\"shard\"");
  if (c.shard.count < 1 || c.shard.index < 0 || c.shard.index >= c.shard.count)
    refuse(path, fmt::format("malformed batch summary: shard {} does not exist (K counts from 0 "
                             "and is below N)",
                             shard_name(c.shard)));
  const auto& rule = field(sec, "rule", path, "\"shard\"");
  if (!rule.is_string() || rule.get<std::string>() != kRule)
    refuse(path, fmt::format("split by rule {}, not \"{}\" (written by another robocal version?)",
                             rule.dump(), kRule));
  c.folders = string_list(sec, "folders", path, "\"shard\"");
  std::vector<std::string> sorted = c.folders;
  std::sort(sorted.begin(), sorted.end());
  const auto twice = std::adjacent_find(sorted.begin(), sorted.end());
  if (twice != sorted.end())
    refuse(path, fmt::format("malformed batch summary: its folder list names '{}' twice", *twice));
  const int total = int_field(sec, "folders_total", path, "\"shard\"");
  if (total != static_cast<int>(c.folders.size()))
    refuse(path, fmt::format("malformed batch summary: folders_total is {} but the folder list "
                             "has {} folders",
                             total, c.folders.size()));
  const auto taken = string_list(sec, "taken", path, "\"shard\"");
  std::vector<std::string> expected;
  for (const std::size_t p : shard_positions(c.folders, c.shard)) expected.push_back(c.folders[p]);
  if (taken != expected)
    refuse(path, fmt::format("malformed batch summary: its \"taken\" folders are not shard {} of "
                             "its folder list ({} folders taken, {} expected)",
                             shard_name(c.shard), taken.size(), expected.size()));

  const auto& sessions = doc["sessions"];
  if (!sessions.is_array()) refuse(path, "malformed batch summary: \"sessions\" is not a list");
  int failed = 0;
  for (const auto& row : sessions) {
    const auto& name = field(row, "session", path, "a session");
    const auto& status = field(row, "status", path, "a session");
    if (!name.is_string() || !status.is_string())
      refuse(path, fmt::format("malformed batch summary: session {} has no folder name or status",
                               row.dump()));
    failed += status.get<std::string>() == "ok" ? 0 : 1;
    c.rows.push_back(row);
  }
  std::vector<std::string> names;
  for (const auto& row : c.rows) names.push_back(row["session"].get<std::string>());
  if (names != taken)
    refuse(path, fmt::format("malformed batch summary: its {} sessions are not the {} folders "
                             "shard {} took (the file was cut short or edited?)",
                             names.size(), taken.size(), shard_name(c.shard)));
  const int ok = int_field(doc, "ok", path, "the summary");
  if (int_field(doc, "failed", path, "the summary") != failed ||
      ok != static_cast<int>(c.rows.size()) - failed)
    refuse(path, fmt::format("malformed batch summary: its totals (ok {}, failed {}) do not count "
                             "its sessions ({} ok, {} failed)",
                             ok, doc["failed"].get<int>(), c.rows.size() - failed, failed));
  return c;
}

// Why two folder lists are not the same list (as sets: the order does not matter).
std::string list_difference(std::vector<std::string> a, std::vector<std::string> b,
                            const std::string& b_name) {
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  std::vector<std::string> only_a, only_b;
  std::set_difference(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(only_a));
  std::set_difference(b.begin(), b.end(), a.begin(), a.end(), std::back_inserter(only_b));
  if (!only_a.empty())
    return fmt::format("'{}' is in its list and not in {}'s", only_a.front(), b_name);
  if (!only_b.empty())
    return fmt::format("'{}' is in {}'s list and not in its", only_b.front(), b_name);
  return "";
}

}  // namespace

std::string shard_syntax_error(const std::string& text) {
  const auto slash = text.find('/');
  int k = 0;
  int n = 0;
  if (slash == std::string::npos || !whole_number(std::string_view(text).substr(0, slash), k) ||
      !whole_number(std::string_view(text).substr(slash + 1), n))
    return fmt::format(
        "'{}' is not K/N: two whole numbers, shard K of N counting from 0 (0/4 is the first of 4 "
        "shards, 3/4 the last)",
        text);
  if (n < 1) return fmt::format("'{}': N, the number of shards, must be 1 or more", text);
  if (k >= n)
    return fmt::format(
        "'{}': K counts from 0 and must be below N (the shards of {} are 0/{} to {}/{}; with Slurm "
        "use --array=0-{})",
        text, n, n, n - 1, n, n - 1);
  return "";
}

Shard parse_shard(const std::string& text) {
  const std::string problem = shard_syntax_error(text);
  if (!problem.empty()) throw std::invalid_argument(problem);
  const auto slash = text.find('/');
  return Shard{std::stoi(text.substr(0, slash)), std::stoi(text.substr(slash + 1))};
}

std::vector<std::size_t> shard_positions(const std::vector<std::string>& folders, Shard s) {
  std::vector<std::size_t> order(folders.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return folders[a] < folders[b]; });
  std::vector<std::size_t> taken;
  for (std::size_t p = static_cast<std::size_t>(s.index); p < order.size();
       p += static_cast<std::size_t>(s.count))
    taken.push_back(order[p]);
  std::sort(taken.begin(), taken.end());
  return taken;
}

nlohmann::json shard_section(const std::vector<std::string>& folders, Shard s,
                             const std::vector<std::size_t>& taken) {
  nlohmann::json names = nlohmann::json::array();
  for (const std::size_t p : taken) names.push_back(folders[p]);
  return nlohmann::json{{"index", s.index},   {"count", s.count},
                        {"rule", kRule},      {"folders_total", folders.size()},
                        {"folders", folders}, {"taken", names}};
}

ShardSummary read_shard_summary(const std::string& path) {
  const std::string text = core::read_text_file(path);
  try {
    return ShardSummary{path, nlohmann::json::parse(text)};
  } catch (const nlohmann::json::parse_error& e) {
    refuse(path, fmt::format("not a JSON file ({})", e.what()));
  }
}

nlohmann::json merge_shard_summaries(const std::vector<ShardSummary>& shards) {
  if (shards.empty()) throw InputError("no shard summary given");
  std::vector<CheckedShard> checked;
  checked.reserve(shards.size());
  for (const auto& s : shards) checked.push_back(check_shard_summary(s));

  const CheckedShard& first = checked.front();
  const int n = first.shard.count;
  std::vector<const CheckedShard*> by_index(static_cast<std::size_t>(n), nullptr);
  for (const auto& c : checked) {
    const std::string& path = c.summary->path;
    if (c.shard.count != n)
      refuse(path, fmt::format("shard {} of a split into {}, but {} is shard {} of a split into "
                               "{}: all summaries must come from one --shard K/N split",
                               shard_name(c.shard), c.shard.count, first.summary->path,
                               shard_name(first.shard), n));
    const std::string diff = list_difference(c.folders, first.folders, first.summary->path);
    if (!diff.empty())
      refuse(path, fmt::format("its folder list ({} folders) is not the list of {} ({} folders): "
                               "{}; every shard must be given the same folders",
                               c.folders.size(), first.summary->path, first.folders.size(), diff));
    auto& slot = by_index[static_cast<std::size_t>(c.shard.index)];
    if (slot != nullptr)
      refuse(path,
             fmt::format("shard {} again: {} is shard {} too (give each shard's summary once)",
                         shard_name(c.shard), slot->summary->path, shard_name(c.shard)));
    slot = &c;
  }
  std::vector<std::string> missing, given;
  for (int k = 0; k < n; ++k) {
    const auto* c = by_index[static_cast<std::size_t>(k)];
    if (c == nullptr)
      missing.push_back(fmt::format("{}/{}", k, n));
    else
      given.push_back(fmt::format("{}/{} ({})", k, n, c->summary->path));
  }
  if (!missing.empty())
    throw InputError(fmt::format(
        "shard{} {} missing: no summary given for {} (given: {}); batch-merge needs the summary "
        "of every shard 0/{} to {}/{}",
        missing.size() > 1 ? "s" : "", fmt::join(missing, ", "), missing.size() > 1 ? "them" : "it",
        fmt::join(given, ", "), n, n - 1, n));

  // The sessions in the order the folders were given (to shard 0).
  std::map<std::string, const nlohmann::json*> row_of;
  for (const auto& c : checked)
    for (const auto& row : c.rows) row_of[row["session"].get<std::string>()] = &row;
  std::vector<nlohmann::json> rows;
  rows.reserve(by_index.front()->folders.size());
  for (const auto& folder : by_index.front()->folders) rows.push_back(*row_of.at(folder));
  return batch_summary(rows);
}

}  // namespace robocal::app
