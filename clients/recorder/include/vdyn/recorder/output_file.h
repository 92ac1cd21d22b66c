// The files vdyn-recorder writes (recordings, recovered copies, CSV, figures): never over one of
// the command's inputs, and never in place.
//
//   - An output that is the same file as an input - by device and inode, so whatever the spelling:
//     `./run.mcap`, an absolute path, a symlink, a hard link - is refused before anything is
//     written (and checked again just before the output takes its name).
//   - The output is written to a temporary file beside its destination (`run.partial-Xy12Ab.csv`:
//     the same folder, so the rename is atomic) and renamed over the destination only when it is
//     complete. An error or a crash leaves the destination as it was: never a half file under
//     the final name, never a truncated input.
//   - A symlink as destination keeps pointing where it did: its target is replaced.
// One helper for every command; mcap::Writer uses it too.
#pragma once

#include <filesystem>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <vector>

namespace vdyn::recorder {

// An output that must not be written (it is an input, a folder, or cannot be created).
class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// True when both paths name one existing file (device and inode; symlinks followed).
bool SameFile(const std::filesystem::path& a, const std::filesystem::path& b);

// Throws OutputError when `dest` is one of `inputs` (SameFile) or an existing folder.
void CheckNotAnInput(const std::filesystem::path& dest,
                     const std::vector<std::filesystem::path>& inputs);

// Where a write to `dest` really lands: the target of a symlink (followed to the end), else dest.
std::filesystem::path WriteTarget(const std::filesystem::path& dest);

class OutputFile {
 public:
  // Checks `dest` against `inputs`, creates its folder, and opens a new temporary file beside it.
  // Throws OutputError saying why not.
  OutputFile(std::filesystem::path dest, std::vector<std::filesystem::path> inputs);
  ~OutputFile();  // not committed: the temporary file is removed, the destination untouched
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  const std::filesystem::path& dest() const { return dest_; }
  const std::filesystem::path& temp() const { return temp_; }
  // The temporary file, open for writing (-1 once released or committed).
  int fd() const { return fd_; }
  // Hands the descriptor to the caller (who closes it), e.g. to a FILE*; the file stays ours.
  int Release();

  // Flushes the temporary file to the disk, checks the destination again, and renames the
  // temporary file over it. Throws OutputError (the temporary file is then removed).
  void Commit();
  // Removes the temporary file (what the destructor does).
  void Abandon();
  // Closes the temporary file and leaves it where it is, under its temporary name (a live
  // recording that could not be finished: its data stay for `vdyn-recorder recover`).
  void Keep();

 private:
  std::filesystem::path dest_;    // as given (messages name it)
  std::filesystem::path target_;  // where it lands (a symlink's target)
  std::filesystem::path temp_;
  std::vector<std::filesystem::path> inputs_;
  int fd_ = -1;
  bool done_ = false;
};

// Moves a finished file (made by another program, e.g. gnuplot) over `dest` as Commit does:
// checked against `inputs` first. Throws OutputError.
void MoveInto(const std::filesystem::path& finished, const std::filesystem::path& dest,
              const std::vector<std::filesystem::path>& inputs);

}  // namespace vdyn::recorder
