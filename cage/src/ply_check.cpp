// The PLY checks of ply_check.h. Why each check exists (most are libFuzzer findings against CGAL 5.5, kept in
// fuzz/regressions/cgal_ply/) and why a file that passes leaves CGAL nothing unsafe to do: docs/cages.md,
// "PLY checks".
#include "ply_check.h"

#include <cctype>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <vector>

#include "lidef/errors.h"

namespace lidef {
namespace {

// A scalar type as CGAL 5.5 names it (PLY_reader.h, TRY_TO_GENERATE_PROPERTY); bytes == 0: a name CGAL does
// not know, and then leaves the whole property out.
struct PlyType {
  int bytes = 0;
  bool is_signed = false, is_float = false;
  long long min = 0, max = 0;  // an integer type's range
};

PlyType ply_type(const std::string& t) {
  if (t == "char" || t == "int8") return {1, true, false, -128, 127};
  if (t == "uchar" || t == "uint8") return {1, false, false, 0, 255};
  if (t == "short" || t == "int16") return {2, true, false, -32768, 32767};
  if (t == "ushort" || t == "uint16") return {2, false, false, 0, 65535};
  if (t == "int" || t == "int32") return {4, true, false, -2147483648LL, 2147483647LL};
  if (t == "uint" || t == "uint32") return {4, false, false, 0, 4294967295LL};
  if (t == "float" || t == "float32") return {4, true, true, 0, 0};
  if (t == "double" || t == "float64") return {8, true, true, 0, 0};
  return {};
}

struct PlyProperty {
  bool list = false;
  PlyType count, item;  // a scalar's type is `item`
};
struct PlyElement {
  std::string name;
  unsigned long long count = 0;
  std::vector<PlyProperty> props;
};
struct PlyHeader {
  bool ascii = true, little = true;
  std::vector<PlyElement> elements;
  bool cgal_refuses = false;  // a line CGAL's `init` returns false on: CGAL then reads no body
};

void require_printable(const std::string& path, const std::string& line, long ln) {
  for (const char c : line)
    if ((static_cast<unsigned char>(c) < 0x20 && c != '\t') || static_cast<unsigned char>(c) >= 0x7f)
      throw InputError(path, "header: a byte that is not printable ASCII (a PLY header is text)", ln);
}

// One `property` line after its keyword, read as CGAL's `init` reads it (a list's count type must be an
// integer type there); a property of a type CGAL does not know is left out, as CGAL leaves it out.
void read_property(const std::string& path, std::istringstream& words, long ln, PlyHeader& h) {
  std::string type, second, third, name;
  if (!(words >> type >> second) || (type == "list" && !(words >> third >> name))) {
    h.cgal_refuses = true;
    return;
  }
  if (h.elements.empty()) throw InputError(path, "header: 'property' before any 'element' line", ln);
  PlyProperty p;
  p.list = type == "list";
  p.item = ply_type(p.list ? third : type);
  if (p.list) p.count = ply_type(second);
  if (p.item.bytes == 0 || (p.list && (p.count.bytes == 0 || p.count.is_float))) return;
  h.elements.back().props.push_back(p);
}

// The header up to `end_header`, line by line as CGAL's `init` reads it: line 1 starts with "ply", line 2 is
// "format <format> <version>", later lines start with a keyword; other keywords are skipped.
PlyHeader read_header(const std::string& path, std::istream& in, std::uintmax_t file_size) {
  PlyHeader h;
  std::string line;
  for (long ln = 1; std::getline(in, line); ++ln) {
    // A file saved with CRLF line ends: CGAL's word reads take the '\r' as white space, and so does this.
    if (!line.empty() && line.back() == '\r') line.pop_back();
    require_printable(path, line, ln);
    std::istringstream words(line);
    std::string keyword;
    if (!(words >> keyword)) h.cgal_refuses = true;
    if (ln == 1 && keyword != "ply") h.cgal_refuses = true;
    if (ln == 2) {
      std::string format, version;
      if (!(words >> format >> version) ||
          (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian"))
        h.cgal_refuses = true;
      h.ascii = format == "ascii";
      h.little = format == "binary_little_endian";
    } else if (ln > 2 && keyword == "property") {
      read_property(path, words, ln, h);
    } else if (ln > 2 && keyword == "element") {
      std::string name;
      unsigned long long count = 0;  // operator>>, as CGAL reads it: "-1" wraps, "12x" is 12
      if (!(words >> name >> count)) h.cgal_refuses = true;
      // An entry takes at least one byte: a larger count kept CGAL looping
      // (fuzz/regressions/cgal_ply/hang_*).
      if (!h.cgal_refuses && count > file_size)
        throw InputError(path,
                         "element '" + name + "' declares " + std::to_string(count) +
                             " entries, more than the file's " + std::to_string(file_size) +
                             " bytes can hold",
                         ln);
      h.elements.push_back({name, count, {}});
    } else if (ln > 2 && keyword == "end_header") {
      return h;
    }
    if (h.cgal_refuses) return h;
  }
  // Without `end_header` CGAL's `init` reads to the end of the file and succeeds; CGAL then reads the
  // elements from a failed stream into uninitialized list counts (out of memory under CI's libFuzzer run).
  throw InputError(path, "header: no 'end_header' line");
}

// Walks the body value by value as CGAL will read it, refusing what would make CGAL read garbage: a value
// missing at the end of the file (a failed read leaves CGAL's list count uninitialized), a negative list
// count or one larger than the rest of the file (CGAL resizes a vector to it first), and an ASCII value CGAL
// would read only in part or not at all (its next read would start inside a token; with every value whole,
// CGAL's reads and this walk see the same values).
class BodyWalk {
 public:
  BodyWalk(const std::string& path, std::istream& in, const PlyHeader& h, std::uintmax_t file_size)
      : path_(path), in_(in), h_(h), size_(file_size) {
    const std::streamoff at = in.tellg();
    at_ = at < 0 ? file_size : static_cast<std::uintmax_t>(at);
  }

  void run() {
    for (const PlyElement& e : h_.elements)
      for (unsigned long long i = 0; i < e.count; ++i)
        for (const PlyProperty& p : e.props) {
          const long long n = p.list ? value(p.count, e, i) : 1;
          if (p.list && n < 0) fail(e, i, "a negative list count (" + std::to_string(n) + ")");
          if (p.list && static_cast<unsigned long long>(n) > left() / (h_.ascii ? 1 : p.item.bytes))
            fail(e, i, "a list of " + std::to_string(n) + " items, more than the rest of the file holds");
          for (long long k = 0; k < n; ++k) value(p.item, e, i);
        }
  }

 private:
  // Bytes after the last value read. An ASCII walk asks the stream only here (tellg is a system call).
  std::uintmax_t left() {
    if (h_.ascii) {
      const std::streamoff at = in_.tellg();
      at_ = at < 0 ? size_ : static_cast<std::uintmax_t>(at);
    }
    return at_ > size_ ? 0 : size_ - at_;
  }

  [[noreturn]] void fail(const PlyElement& e, unsigned long long i, const std::string& what) const {
    throw InputError(path_, "element '" + e.name + "' entry " + std::to_string(i + 1) + " of " +
                                std::to_string(e.count) + ": " + what);
  }

  // Reads one value of type t; an integer comes back (a float's value is not needed: 0).
  long long value(const PlyType& t, const PlyElement& e, unsigned long long i) {
    return h_.ascii ? ascii_value(t, e, i) : binary_value(t, e, i);
  }

  long long binary_value(const PlyType& t, const PlyElement& e, unsigned long long i) {
    if (left() < static_cast<std::uintmax_t>(t.bytes)) fail(e, i, "the file ends inside this entry");
    unsigned char b[8] = {0};
    in_.read(reinterpret_cast<char*>(b), t.bytes);
    at_ += static_cast<std::uintmax_t>(t.bytes);
    if (t.is_float) return 0;
    unsigned long long v = 0;
    for (int k = 0; k < t.bytes; ++k)
      v |= static_cast<unsigned long long>(b[h_.little ? k : t.bytes - 1 - k]) << (8 * k);
    const unsigned long long sign = 1ULL << (8 * t.bytes - 1);
    if (t.is_signed && (v & sign)) return static_cast<long long>(v) - static_cast<long long>(sign << 1);
    return static_cast<long long>(v);
  }

  long long ascii_value(const PlyType& t, const PlyElement& e, unsigned long long i) {
    std::string tok;
    if (!(in_ >> tok)) fail(e, i, "the file ends inside this entry");
    if (t.is_float) {
      // CGAL's iformat(double) takes a sign, then the longest run of [0-9.eE+-], and sscanf's it.
      const size_t start = tok[0] == '+' || tok[0] == '-' ? 1 : 0;
      for (size_t k = start; k < tok.size(); ++k)
        if (!std::isdigit(static_cast<unsigned char>(tok[k])) &&
            std::string(".eE+-").find(tok[k]) == std::string::npos)
          fail(e, i, "'" + tok + "' is not a number");
      double d = 0;
      if (std::sscanf(tok.c_str(), "%lf", &d) != 1) fail(e, i, "'" + tok + "' is not a number");
      return 0;
    }
    // An integer type: CGAL's operator>> stops at the first non-digit and wraps or saturates out of range.
    size_t k = tok[0] == '+' || tok[0] == '-' ? 1 : 0;
    bool digits = k < tok.size();
    for (; k < tok.size(); ++k) digits = digits && std::isdigit(static_cast<unsigned char>(tok[k]));
    long long v = 0;
    if (!digits || tok.size() > 12 || std::sscanf(tok.c_str(), "%lld", &v) != 1 || v < t.min || v > t.max)
      fail(e, i, "'" + tok + "' is not an integer in the range of its type");
    return v;
  }

  const std::string& path_;
  std::istream& in_;
  const PlyHeader& h_;
  std::uintmax_t size_, at_ = 0;
};

}  // namespace

void check_ply_before_cgal(const std::string& path, std::uintmax_t file_size) {
  std::ifstream in(path, std::ios::binary);
  const PlyHeader h = read_header(path, in, file_size);
  if (!h.cgal_refuses) BodyWalk(path, in, h, file_size).run();
}

}  // namespace lidef
