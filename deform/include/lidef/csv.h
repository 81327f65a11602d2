// One CSV line split into fields (RFC 4180 quoting: a quoted field may hold commas and doubled quotes). The
// comparison table (lidef-compare's table.csv) quotes its free-text columns; the studio's comparison view and
// `lidef reproduce` read it back with this.
#pragma once
#include <string>
#include <vector>

namespace lidef {

inline std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  bool quoted = false;
  for (size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        cur += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        cur += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      out.push_back(cur);
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}

}  // namespace lidef
