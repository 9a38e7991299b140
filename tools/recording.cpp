#include "tools/recording.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include "daemon/recorder.hpp"

namespace pvcgel::tools {

namespace {
std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(item);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}
bool to_number(const std::string& s, double& v) {
  if (s == "nan" || s == "-nan") {
    v = NAN;
    return true;
  }
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  return ec == std::errc() && p == s.data() + s.size();
}
/// A finite but impossible u_V or y_um is a corrupt file, not a measurement: name it.
void check_physical(const std::string& path, const std::vector<std::string>& names,
                    const std::vector<std::vector<std::string>>& cells, const std::vector<int>& line_of_row) {
  for (const auto& [column, bound, unit] : {std::tuple{"u_V", kMaxPhysicalVoltage_V, "V"},
                                            std::tuple{"y_um", kMaxPhysicalDisplacement_um, "um"}}) {
    const auto c = static_cast<std::size_t>(std::find(names.begin(), names.end(), column) - names.begin());
    for (std::size_t r = 0; r < cells.size(); ++r) {
      double v = 0.0;
      if (to_number(cells[r][c], v) && std::isfinite(v) && std::abs(v) > bound)
        throw std::runtime_error(path + ":" + std::to_string(line_of_row[r]) + ": " + column + " = " + cells[r][c] +
                                 " is not physical (|" + column + "| <= " + std::to_string(static_cast<long>(bound)) +
                                 " " + unit + ")");
    }
  }
}

}  // namespace

const std::vector<double>& Recording::col(const std::string& name) const {
  const auto it = numeric.find(name);
  if (it == numeric.end()) throw std::runtime_error(path + ": no numeric column '" + name + "'");
  return it->second;
}

namespace {

/// The file's rows as text: `# key: value` header lines into rec.header, the column names, each data row
/// with its line number. A last line cut by a crash is counted in rec.truncated_rows, not read.
struct CsvRows {
  std::vector<std::string> names;
  std::vector<std::vector<std::string>> cells;
  std::vector<int> line_of_row;
};

CsvRows read_rows(std::istream& in, Recording& rec) {
  const std::string& path = rec.path;
  CsvRows out;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    // A writer killed mid-line leaves a last line without its newline: skip and count it.
    if (in.eof()) {
      if (!out.names.empty() && !line.empty()) ++rec.truncated_rows;
      break;
    }
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    if (line[0] == '#') {
      const auto colon = line.find(':');
      if (colon != std::string::npos) {
        auto key = line.substr(1, colon - 1);
        auto value = line.substr(colon + 1);
        key.erase(0, key.find_first_not_of(' '));
        value.erase(0, value.find_first_not_of(' '));
        rec.header[key] = value;
      }
      continue;
    }
    if (out.names.empty()) {
      out.names = split(line);
      for (const char* required : daemon::kRecordingRequiredColumns)
        if (std::find(out.names.begin(), out.names.end(), required) == out.names.end())
          throw std::runtime_error(path + ":" + std::to_string(lineno) + ": header lacks column '" + required +
                                   "' (need at least t_s,u_V,y_um)");
      continue;
    }
    auto row = split(line);
    if (row.size() != out.names.size())
      throw std::runtime_error(path + ":" + std::to_string(lineno) + ": " + std::to_string(row.size()) +
                               " fields, header has " + std::to_string(out.names.size()));
    out.cells.push_back(std::move(row));
    out.line_of_row.push_back(lineno);
  }
  if (out.names.empty()) throw std::runtime_error(path + ": no header row");
  return out;
}

/// Columns that parse as numbers everywhere into rec.numeric, the others into rec.text.
void store_columns(const CsvRows& rows, Recording& rec) {
  for (size_t c = 0; c < rows.names.size(); ++c) {
    std::vector<double> v(rows.cells.size());
    bool numeric = true;
    for (size_t r = 0; r < rows.cells.size() && numeric; ++r) numeric = to_number(rows.cells[r][c], v[r]);
    if (numeric) rec.numeric[rows.names[c]] = std::move(v);
    else {
      auto& t = rec.text[rows.names[c]];
      for (const auto& row : rows.cells) t.push_back(row[c]);
    }
  }
  for (const char* required : daemon::kRecordingRequiredColumns)
    if (!rec.numeric.count(required)) throw std::runtime_error(rec.path + ": column '" + required + "' is not numeric");
}

/// Drops the rows whose t_s, u_V or y_um is not finite (with keep_invalid_rows, only those without a
/// finite t_s), counting them; returns the line number of each row kept.
std::vector<int> drop_invalid_rows(Recording& rec, const std::vector<int>& line_of_row, bool keep_invalid_rows) {
  const auto& t0 = rec.numeric["t_s"];
  std::vector<bool> keep(t0.size(), true);
  for (size_t r = 0; r < t0.size(); ++r) {
    for (const char* k : daemon::kRecordingRequiredColumns)
      if (!std::isfinite(rec.numeric[k][r])) keep[r] = false;
    if (!keep[r]) ++rec.invalid_rows;
    if (keep_invalid_rows && std::isfinite(t0[r])) keep[r] = true;
  }
  auto keep_rows = [&](auto& columns) {
    for (auto& [name, v] : columns) {
      std::remove_reference_t<decltype(v)> kept;
      for (size_t r = 0; r < v.size(); ++r)
        if (keep[r]) kept.push_back(v[r]);
      v = std::move(kept);
    }
  };
  keep_rows(rec.numeric);
  keep_rows(rec.text);
  std::vector<int> lines;
  for (size_t r = 0; r < keep.size(); ++r)
    if (keep[r]) lines.push_back(line_of_row[r]);
    else ++rec.skipped_rows;
  return lines;
}

/// The sample time: time must increase uniformly (1% tolerance); a bad step names its line.
double uniform_sample_time(const Recording& rec, const std::vector<int>& lines) {
  const auto& t = rec.numeric.at("t_s");
  if (t.size() < 2) throw std::runtime_error(rec.path + ": fewer than 2 valid rows");
  const double dt = (t.back() - t.front()) / static_cast<double>(t.size() - 1);
  if (!(dt > 0.0)) throw std::runtime_error(rec.path + ": time does not increase");
  for (size_t r = 1; r < t.size(); ++r) {
    const double step = t[r] - t[r - 1];
    if (!(step > 0.0) || std::abs(step - dt) > 0.01 * dt + 1e-9)
      throw std::runtime_error(rec.path + ":" + std::to_string(lines[r]) + ": non-uniform or non-monotone time (step " +
                               std::to_string(step) + " s, expected " + std::to_string(dt) + " s)" +
                               (rec.skipped_rows ? " after skipping " + std::to_string(rec.skipped_rows) + " invalid rows" : ""));
  }
  return dt;
}

}  // namespace

Recording read_recording(const std::string& path, bool keep_invalid_rows) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open recording '" + path + "'");
  Recording rec;
  rec.path = path;
  const CsvRows rows = read_rows(in, rec);
  check_physical(path, rows.names, rows.cells, rows.line_of_row);
  if (rows.cells.size() < 2) throw std::runtime_error(path + ": fewer than 2 data rows");
  store_columns(rows, rec);
  const auto lines = drop_invalid_rows(rec, rows.line_of_row, keep_invalid_rows);
  rec.sample_time_s = uniform_sample_time(rec, lines);
  return rec;
}

}  // namespace pvcgel::tools
