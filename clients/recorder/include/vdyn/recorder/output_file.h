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
//   - A destination that is not a regular file is never replaced: a FIFO or a character device
//     (`/dev/null`, a terminal) is written into as a stream, in place; an open descriptor named
//     as a file (`/dev/stdout`, `/dev/stderr`, `/dev/fd/N`, `/proc/self/fd/N`) is written
//     through that descriptor; a block device, a socket or anything else is refused. So is a
//     name that ends with a slash (no file name: nothing is created, not even its folder).
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

// How an output is written: beside its name then renamed (a regular file, or none yet), or into
// it as a stream (a FIFO, a character device, an open descriptor).
enum class OutputKind { kFile, kStream };
// Throws OutputError for a destination that cannot be written (a name ending with a slash, a
// block device, a socket); else how it is written. Creates nothing.
OutputKind CheckOutputKind(const std::filesystem::path& dest);
// True for a name of the standard output (/dev/stdout, /dev/fd/1, /proc/self/fd/1): a command
// writing its output there says what it did on the standard error.
bool NamesStandardOutput(const std::filesystem::path& dest);

class OutputFile {
 public:
  // Checks `dest` against `inputs`, creates its folder, and opens a new temporary file beside it.
  // Throws OutputError saying why not.
  OutputFile(std::filesystem::path dest, std::vector<std::filesystem::path> inputs);
  ~OutputFile();  // not committed: the temporary file is removed, the destination untouched
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  const std::filesystem::path& dest() const { return dest_; }
  // The temporary file; the destination itself for a stream.
  const std::filesystem::path& temp() const { return stream_ ? dest_ : temp_; }
  bool stream() const { return stream_; }
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
  bool stream_ = false;  // written in place (OutputKind::kStream): no temporary file, no rename
};

// Moves a finished file (made by another program, e.g. gnuplot) over `dest` as Commit does:
// checked against `inputs` first; a `dest` that is not a regular file is refused. Throws
// OutputError.
void MoveInto(const std::filesystem::path& finished, const std::filesystem::path& dest,
              const std::vector<std::filesystem::path>& inputs);

}  // namespace vdyn::recorder
