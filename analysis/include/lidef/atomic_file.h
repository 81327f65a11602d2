// Writing outputs without ever leaving a half-written file: write to a temp file beside the target,
// then rename over it (rename is atomic on POSIX within one file system).
#pragma once
#include <functional>
#include <ostream>
#include <string>

namespace lidef {

// Calls `writer` with a stream to a temporary file next to `path`, then renames it to `path`.
// If `writer` throws or the stream fails, the temporary is removed and `path` is left untouched.
void write_file_atomic(const std::string& path, const std::function<void(std::ostream&)>& writer);

// Creates `dir` (and parents) if missing. Throws InputError naming the directory on failure.
void ensure_directory(const std::string& dir);

}  // namespace lidef
