// What CGAL 5.5's PLY reader trusts without checking, checked before it reads a file (private to lidef_cage).
#pragma once
#include <cstdint>
#include <string>

namespace lidef {

// Reads the header the way CGAL 5.5 does (PLY_reader.h: `init`) and walks the body as that header describes
// it. Throws InputError(path, ...) for a file CGAL would read out of bounds, into uninitialized counts, or
// for ever: a header byte that is not printable ASCII, no `end_header` line, an element count or a list count
// larger than the rest of the file, a negative list count, a body that ends before the header's entries do,
// and an ASCII value CGAL would read only in part. The argument, case by case, is in docs/cages.md ("PLY
// checks"). `file_size`: the file's size in bytes.
void check_ply_before_cgal(const std::string& path, std::uintmax_t file_size);

}  // namespace lidef
