// Writing outputs without ever leaving a half-written file: write to a temporary file beside the target, then
// rename it over the target (atomic on POSIX within one file system). A process killed at any moment leaves
// the previous file or the new one, never a mixture; a left-over temporary is never read (its name differs).
// The one implementation for the core, the CLI, the OpenCL kernel cache and the studio.
#pragma once
#include <functional>
#include <ostream>
#include <string>

namespace lidef {

// A fresh temporary name beside `path`: "<path>.tmp.<pid>.<n><ext>", unique per process and call, so that two
// threads or processes writing the same target never share a temporary. `ext` keeps writers that pick the
// format from the extension (VTK, PNG) happy.
std::string temp_path_beside(const std::string& path, const std::string& ext = "");

// Renames `tmp` over `path`; on failure removes `tmp` and throws InputError(path, ...).
void commit_temp_file(const std::string& tmp, const std::string& path);

// Calls `writer` with a stream to a temporary file next to `path`, then renames it to `path`.
// If `writer` throws or the stream fails, the temporary is removed and `path` is left untouched
// (InputError(path, ...) for a stream failure).
void write_file_atomic(const std::string& path, const std::function<void(std::ostream&)>& writer);

// The same for writers that take a file name (VTK's, PNG's): `write(tmp)` must create the temporary `tmp`
// (named with `ext`) or throw; a missing temporary afterwards counts as a failed write.
void write_file_atomic_via_path(const std::string& path, const std::string& ext,
                                const std::function<void(const std::string& tmp)>& write);

// Creates `dir` (and parents) if missing. Throws InputError naming the directory on failure.
void ensure_directory(const std::string& dir);

}  // namespace lidef
