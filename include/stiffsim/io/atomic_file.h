#pragma once
// Output files appear whole or not at all: each is written under
// "<path>.tmp" and renamed to <path> when complete, so a reader (or a run
// that failed half-way) never leaves a half-written file under the name.

#include <cstdio>
#include <string>

namespace stiffsim {

// Renames the finished `temp` to `path`; on failure removes `temp` and
// throws std::runtime_error naming both.
void commit_temporary(const std::string& temp, const std::string& path);

// Closes `file`, the temporary `temp` being written for `path`, and commits
// it; when `written` is false (a write failed) or the close fails, removes
// `temp` and throws std::runtime_error naming it with errno's reason.
void close_and_commit(std::FILE* file, bool written, const std::string& temp,
                      const std::string& path);

// Writes `text` to "<path>.tmp" and commits it to `path`; throws
// std::runtime_error naming the file (the temporary removed) on failure.
void write_file_atomically(const std::string& path, const std::string& text);

}  // namespace stiffsim
