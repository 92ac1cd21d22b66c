#include "vdyn/recorder/output_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <optional>
#include <random>
#include <string_view>

namespace vdyn::recorder {

namespace fs = std::filesystem;

namespace {

std::string Errno() {
  return std::strerror(errno);
}

// A name for the temporary file beside `target`: "run.partial-Xy12Ab.csv" (the extension kept,
// so a tool that goes by it still recognises a file left by a crash).
fs::path TempName(const fs::path& target, std::mt19937_64& rng) {
  static constexpr char kChars[] = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789";
  std::string tag;
  for (int i = 0; i < 6; ++i) tag += kChars[rng() % (sizeof kChars - 1)];
  fs::path p = target;
  p.replace_filename(target.stem().string() + ".partial-" + tag + target.extension().string());
  return p;
}

void SyncFolder(const fs::path& file) {
  const fs::path dir = file.has_parent_path() ? file.parent_path() : fs::path(".");
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd >= 0) {
    ::fsync(fd);  // the rename reaches the disk too (best effort: some file systems refuse)
    ::close(fd);
  }
}

// The descriptor a path names, when it names one: /dev/stdout, /dev/stderr, /dev/fd/N,
// /proc/self/fd/N (as given: writing through the name would reopen, or replace, what it points
// at).
std::optional<int> DescriptorNamed(const fs::path& dest) {
  const std::string s = dest.lexically_normal().string();
  if (s == "/dev/stdout") return 1;
  if (s == "/dev/stderr") return 2;
  for (const char* prefix : {"/dev/fd/", "/proc/self/fd/"}) {
    const std::string_view p(prefix);
    if (s.rfind(p, 0) != 0 || s.size() == p.size() || s.size() > p.size() + 6) continue;
    int n = 0;
    for (std::size_t i = p.size(); i < s.size(); ++i) {
      if (s[i] < '0' || s[i] > '9') return std::nullopt;
      n = n * 10 + (s[i] - '0');
    }
    return n;
  }
  return std::nullopt;
}

}  // namespace

OutputKind CheckOutputKind(const fs::path& dest) {
  const std::string s = dest.string();
  if (s.empty() || s.back() == '/' || dest.filename() == "." || dest.filename() == "..") {
    throw OutputError((s.empty() ? std::string("''") : s) +
                      ": not a file name (it ends with a slash or names a folder); give a file "
                      "name for the output (nothing was written)");
  }
  if (DescriptorNamed(dest)) return OutputKind::kStream;
  struct stat st {};
  if (::stat(dest.c_str(), &st) != 0 || S_ISREG(st.st_mode) || S_ISDIR(st.st_mode)) {
    return OutputKind::kFile;  // none yet, a file to replace, or a folder (CheckNotAnInput)
  }
  if (S_ISFIFO(st.st_mode) || S_ISCHR(st.st_mode)) return OutputKind::kStream;
  throw OutputError(s + " is " +
                    (S_ISBLK(st.st_mode)    ? "a block device"
                     : S_ISSOCK(st.st_mode) ? "a socket"
                                            : "not a regular file") +
                    ": an output is written to a file, a FIFO or a character device; it is left as "
                    "it was (nothing was written)");
}

bool NamesStandardOutput(const fs::path& dest) {
  return DescriptorNamed(dest) == 1;
}

bool SameFile(const fs::path& a, const fs::path& b) {
  struct stat sa {
  }, sb{};
  if (::stat(a.c_str(), &sa) != 0 || ::stat(b.c_str(), &sb) != 0) return false;
  return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

void CheckNotAnInput(const fs::path& dest, const std::vector<fs::path>& inputs) {
  std::error_code ec;
  if (fs::is_directory(dest, ec)) {
    throw OutputError(dest.string() + " is a folder: give a file name for the output");
  }
  for (const fs::path& in : inputs) {
    if (SameFile(dest, in)) {
      const bool spelled =
          fs::absolute(dest).lexically_normal() == fs::absolute(in).lexically_normal();
      throw OutputError(
          "the output " + dest.string() + " is the input " +
          (spelled ? std::string("itself") : in.string() + " (the same file under another name)") +
          ": it would be destroyed; choose another output file (nothing was written)");
    }
  }
}

fs::path WriteTarget(const fs::path& dest) {
  fs::path p = dest;
  std::error_code ec;
  for (int i = 0; i < 40 && fs::is_symlink(p, ec); ++i) {
    const fs::path link = fs::read_symlink(p, ec);
    if (ec) break;
    p = link.is_absolute() ? link : p.parent_path() / link;
  }
  return p;
}

OutputFile::OutputFile(fs::path dest, std::vector<fs::path> inputs)
    : dest_(std::move(dest)), target_(WriteTarget(dest_)), inputs_(std::move(inputs)) {
  const OutputKind kind = CheckOutputKind(dest_);
  CheckNotAnInput(dest_, inputs_);
  if (kind == OutputKind::kStream) {
    // Into it, as a shell's `>` would (a FIFO blocks here until someone reads it); never
    // unlinked, never replaced.
    stream_ = true;
    const std::optional<int> named = DescriptorNamed(dest_);
    fd_ = named ? ::fcntl(*named, F_DUPFD_CLOEXEC, 3)
                : ::open(dest_.c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC);
    if (fd_ < 0 && errno == EINTR) {
      throw OutputError(dest_.string() + ": interrupted while waiting for a reader of it (a FIFO "
                        "opens for writing when something opens it for reading)");
    }
    if (fd_ < 0) throw OutputError(dest_.string() + ": cannot write into it: " + Errno());
    return;
  }
  std::error_code ec;
  if (target_.has_parent_path()) {
    fs::create_directories(target_.parent_path(), ec);
    if (ec) {
      throw OutputError(dest_.string() + ": cannot create its folder " +
                        target_.parent_path().string() + ": " + ec.message());
    }
  }
  std::mt19937_64 rng(std::random_device{}() ^ static_cast<std::uint64_t>(::getpid()));
  for (int attempt = 0; attempt < 100 && fd_ < 0; ++attempt) {
    temp_ = TempName(target_, rng);
    fd_ = ::open(temp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd_ < 0 && errno != EEXIST) {
      throw OutputError(dest_.string() + ": cannot create a file beside it (" + temp_.string() +
                        "): " + Errno());
    }
  }
  if (fd_ < 0) throw OutputError(dest_.string() + ": no free temporary name beside it");
}

OutputFile::~OutputFile() {
  Abandon();
}

int OutputFile::Release() {
  const int fd = fd_;
  fd_ = -1;
  return fd;
}

void OutputFile::Keep() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  done_ = true;
}

void OutputFile::Abandon() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!done_ && !stream_ && !temp_.empty()) ::unlink(temp_.c_str());
  done_ = true;
}

void OutputFile::Commit() {
  if (done_) throw OutputError(dest_.string() + ": already written");
  if (stream_) {
    const int fd = fd_;
    fd_ = -1;
    done_ = true;
    if (fd >= 0 && ::close(fd) != 0) {
      throw OutputError(dest_.string() + ": writing failed: " + Errno());
    }
    return;
  }
  const int fd = fd_ >= 0 ? fd_ : ::open(temp_.c_str(), O_RDONLY | O_CLOEXEC);
  fd_ = -1;
  std::string why;
  if (fd < 0) {
    why = Errno();
  } else {
    if (::fsync(fd) != 0) why = Errno();
    if (::close(fd) != 0 && why.empty()) why = Errno();
  }
  if (!why.empty()) {
    Abandon();
    throw OutputError(dest_.string() + ": writing failed: " + why);
  }
  try {
    MoveInto(temp_, target_, inputs_);
  } catch (const OutputError&) {
    Abandon();
    throw;
  }
  done_ = true;
}

void MoveInto(const fs::path& finished, const fs::path& dest, const std::vector<fs::path>& inputs) {
  // Checked again: an input may have been put there since the output was started.
  CheckNotAnInput(dest, inputs);
  if (CheckOutputKind(dest) != OutputKind::kFile) {
    throw OutputError(dest.string() +
                      " is not a regular file (a FIFO, a device or a descriptor): it is not "
                      "replaced by a finished file; give a folder of its own");
  }
  const fs::path target = WriteTarget(dest);
  if (::rename(finished.c_str(), target.c_str()) != 0) {
    throw OutputError(dest.string() + ": cannot give the finished file its name (rename from " +
                      finished.string() + "): " + Errno());
  }
  SyncFolder(target);
}

}  // namespace vdyn::recorder
