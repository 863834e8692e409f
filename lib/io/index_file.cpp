// The index file format: checking a file when it is opened, handing out its sections, and writing one
// atomically (see kdspace/io/index_file.hpp for the layout).
#include "kdspace/io/index_file.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <new>
#include <string>
#include <stdexcept>
#include <system_error>

#include "crc32c.hpp"
#include "kdspace/detail/huge_pages.hpp"
#include "kdspace/detail/section_thread.hpp"
#include "kdspace/error.hpp"

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "kdspace's index files are read and written in the machine's byte order, which must be little-endian"
#endif

namespace kdspace::io {
namespace {

constexpr unsigned char magic[8] = {0x89, 'K', 'D', 'X', 0x0D, 0x0A, 0x1A, 0x0A};
constexpr std::uint32_t byte_order_mark = 0x01020304u;

// Header fields (offsets from the top of kdspace/io/index_file.hpp).
constexpr std::size_t at_version = 8, at_byte_order = 12, at_kind = 16, at_scalar = 20, at_metric = 24,
                      at_sections = 28, at_dim = 32, at_count = 40, at_file_bytes = 48, at_table_crc = 56,
                      at_header_crc = 60;

template <class V>
V get(const unsigned char* p) {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <class V>
void put(unsigned char* p, V v) {
  std::memcpy(p, &v, sizeof v);
}

std::uint64_t align_up(std::uint64_t v) {
  return (v + index_section_alignment - 1) / index_section_alignment * index_section_alignment;
}

std::string errno_text() {
  return std::strerror(errno);
}

[[noreturn]] void fail_path(const std::string& path, const std::string& what) {
  throw Error(path + ": " + what);
}

// Asks the kernel to back a mapping of an index file with huge pages, before anything in it is read.
// Where the file is not in the page cache (evicted since it was written), Linux then reads it back in
// 2 MiB folios instead of 4 KiB pages, and every later mapping of it takes one page-table entry per
// 2 MiB instead of one fault per 16 pages: kdspace-index-bench measures a 1e6-point tree's load after
// eviction. The whole mapping is advised, not only its 2 MiB-aligned interior as
// detail::advise_huge_pages does for arrays: the advice here chooses how the page cache reads the file
// back, its head and tail included. And it is given by default, unlike the arrays' (off unless
// KDSPACE_HUGE_PAGES=1, detail/huge_pages.hpp): those are fresh memory a huge page at a time, which
// on our VMs cost more to fault in than it saved; here the folios come with the reads from storage,
// and the bench's first load from storage was faster advised (5.1-5.9 ms) than not (10.0-12.0 ms).
// Advice only: where the kernel declines (no transparent huge pages, another file system), nothing
// changes, so a failure is not an error.
void advise_file_huge_pages([[maybe_unused]] void* map, [[maybe_unused]] std::size_t size) {
#if defined(MADV_HUGEPAGE)
  if (size >= kdspace::detail::huge_page_bytes) (void)::madvise(map, size, MADV_HUGEPAGE);
#endif
}

bool known_kind(std::uint32_t v) {
  return v >= 1 && v <= 4;
}

// Memory aligned for any section type, for LoadMode::read and from_bytes.
void* allocate_aligned(std::size_t bytes) {
  return ::operator new (std::max<std::size_t>(bytes, 1), std::align_val_t{index_section_alignment});
}
void free_aligned(void* p) {
  ::operator delete (p, std::align_val_t{index_section_alignment});
}

// An open file descriptor, closed on scope exit.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

// Reads exactly n bytes at `offset`; false at a short read (the file shrank).
bool read_at(int fd, void* dst, std::size_t n, std::uint64_t offset) {
  auto* p = static_cast<unsigned char*>(dst);
  while (n > 0) {
    const ssize_t got =
        ::pread(fd, p, std::min<std::size_t>(n, std::size_t{1} << 30), static_cast<off_t>(offset));
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) return false;
    p += got;
    n -= static_cast<std::size_t>(got);
    offset += static_cast<std::uint64_t>(got);
  }
  return true;
}

// Writes the pieces one after another, in as few calls as the kernel takes (IOV_MAX pieces, at most
// 2 GiB, a call). One call for a whole index file, not one a section: Linux fills the page cache of a
// write in folios as large as the write's span allows, up to 2 MiB where the file offset is a multiple
// of 2 MiB, and a mapping of the file then takes one page-table entry, and one fault, for each 2 MiB
// folio. Written a section at a time, every 2 MiB span that a section boundary falls in was cached in
// small folios, mapped 16 pages a fault: a fresh mapping of 1e6 3-D points (18 MB), just written, took
// 28 faults (12 MB of it in 2 MiB entries), against 14 (16 MB) written at once.
void write_all(int fd, std::vector<iovec> pieces) {
  std::size_t first = 0;
  while (first < pieces.size()) {
    const int count = static_cast<int>(std::min<std::size_t>(pieces.size() - first, IOV_MAX));
    ssize_t put_bytes = ::writev(fd, pieces.data() + first, count);
    if (put_bytes < 0 && errno == EINTR) continue;
    if (put_bytes < 0) throw std::system_error(errno, std::generic_category());
    for (; first < pieces.size() && static_cast<std::size_t>(put_bytes) >= pieces[first].iov_len; ++first)
      put_bytes -= static_cast<ssize_t>(pieces[first].iov_len);
    if (first < pieces.size()) {  // a short write ended inside this piece
      pieces[first].iov_base = static_cast<unsigned char*>(pieces[first].iov_base) + put_bytes;
      pieces[first].iov_len -= static_cast<std::size_t>(put_bytes);
    }
  }
}

std::string hex(std::uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%08x", v);
  return buf;
}

}  // namespace

// ---- names -----------------------------------------------------------------------------------------

const char* name_of(IndexKind kind) {
  switch (kind) {
    case IndexKind::point_tree:
      return "point tree";
    case IndexKind::dynamic_point_tree:
      return "updatable point tree";
    case IndexKind::point_forest:
      return "point forest";
    case IndexKind::box_tree:
      return "box tree";
  }
  return "unknown kind";
}

const char* name_of(SectionType type) {
  switch (type) {
    case SectionType::params:
      return "params";
    case SectionType::nodes:
      return "nodes";
    case SectionType::points:
      return "points";
    case SectionType::point_bytes:
      return "point bytes";
    case SectionType::order:
      return "order";
    case SectionType::ids:
      return "ids";
    case SectionType::removed:
      return "removed";
    case SectionType::dynamic_state:
      return "dynamic state";
    case SectionType::mean:
      return "mean";
    case SectionType::projection:
      return "projection";
    case SectionType::boxes:
      return "boxes";
    case SectionType::references:
      return "references";
    case SectionType::leaf_boxes:
      return "leaf boxes";
    case SectionType::bounds:
      return "bounds";
    case SectionType::leaf_blocks:
      return "leaf blocks";
    case SectionType::graph:
      return "graph";
  }
  return "unknown";
}

const char* name_of(ScalarType type) {
  switch (type) {
    case ScalarType::none:
      return "none";
    case ScalarType::float32:
      return "float32";
    case ScalarType::float64:
      return "float64";
  }
  return "unknown";
}

const char* name_of(MetricId metric) {
  switch (metric) {
    case MetricId::none:
      return "none";
    case MetricId::l2:
      return "l2";
    case MetricId::l1:
      return "l1";
    case MetricId::linf:
      return "linf";
    case MetricId::minkowski:
      return "minkowski";
  }
  return "unknown";
}

std::uint64_t word_of(double v) {
  return get<std::uint64_t>(reinterpret_cast<const unsigned char*>(&v));
}
double double_of(std::uint64_t word) {
  return get<double>(reinterpret_cast<const unsigned char*>(&word));
}

// ---- opening -----------------------------------------------------------------------------------------

std::shared_ptr<const IndexFile> IndexFile::open(const std::string& path, LoadMode mode,
                                                 Checksums checksums) {
  std::shared_ptr<IndexFile> file(new IndexFile());
  file->path_ = path;
  Fd fd{::open(path.c_str(), O_RDONLY | O_CLOEXEC)};
  if (fd.fd < 0) fail_path(path, "cannot open: " + errno_text());
  struct stat st {};
  if (::fstat(fd.fd, &st) != 0) fail_path(path, "cannot open: " + errno_text());
  if (S_ISDIR(st.st_mode)) fail_path(path, "is a directory, not an index file");
  if (!S_ISREG(st.st_mode)) fail_path(path, "not a regular file");
  const auto size = static_cast<std::uint64_t>(st.st_size);
  if (size == 0) fail_path(path, "empty file, not an index");
  if (size > static_cast<std::uint64_t>(SIZE_MAX)) fail_path(path, "file too large");
  file->size_ = static_cast<std::size_t>(size);

  // The magic first, so that a large file of another kind is not read: through the mapping, advised
  // before anything in it is read (a pread() would bring the file's first pages into the page cache
  // in small pages, past the advice).
  const std::size_t head_bytes = std::min<std::size_t>(sizeof magic, file->size_);
  if (mode == LoadMode::map) {
    void* p = ::mmap(nullptr, file->size_, PROT_READ, MAP_PRIVATE, fd.fd, 0);
    if (p == MAP_FAILED) fail_path(path, "cannot memory-map: " + errno_text());
    file->bytes_ = static_cast<const unsigned char*>(p);
    file->mapped_ = true;
    advise_file_huge_pages(p, file->size_);
    if (std::memcmp(file->bytes_, magic, head_bytes) != 0)
      fail_path(path, "not a kdspace index file (bad magic bytes)");
  } else {
    unsigned char head[sizeof magic] = {};
    if (!read_at(fd.fd, head, head_bytes, 0)) fail_path(path, "read error: " + errno_text());
    if (std::memcmp(head, magic, head_bytes) != 0)
      fail_path(path, "not a kdspace index file (bad magic bytes)");
    file->buffer_ = allocate_aligned(file->size_);
    file->bytes_ = static_cast<const unsigned char*>(file->buffer_);
    if (!read_at(fd.fd, file->buffer_, file->size_, 0))
      fail_path(path, "read error (the file changed while being read?): " + errno_text());
  }
  file->check(checksums);
  return file;
}

std::shared_ptr<const IndexFile> IndexFile::from_bytes(const unsigned char* bytes, std::size_t size,
                                                       const std::string& name) {
  std::shared_ptr<IndexFile> file(new IndexFile());
  file->path_ = name;
  file->size_ = size;
  file->buffer_ = allocate_aligned(size);
  if (size > 0) std::memcpy(file->buffer_, bytes, size);
  file->bytes_ = static_cast<const unsigned char*>(file->buffer_);
  file->check(Checksums::now);
  return file;
}

IndexFile::~IndexFile() {
  if (mapped_) ::munmap(const_cast<unsigned char*>(bytes_), size_);
  if (buffer_) free_aligned(buffer_);
}

void IndexFile::fail(const std::string& what) const {
  fail_path(path_, what);
}

std::string IndexFile::describe(const SectionEntry& s) const {
  return std::string("section '") + name_of(s.type) + "'" +
         (s.part ? " of part " + std::to_string(s.part) : "") + " (" + std::to_string(s.length) +
         " bytes at offset " + std::to_string(s.offset) + ")";
}

void IndexFile::check(Checksums checksums) {
  const unsigned char* b = bytes_;
  if (size_ == 0) fail("empty file, not an index");
  if (std::memcmp(b, magic, std::min(size_, sizeof magic)) != 0)
    fail("not a kdspace index file (bad magic bytes)");
  if (size_ < index_header_bytes)
    fail("truncated: " + std::to_string(size_) + " bytes, the header alone takes " +
         std::to_string(index_header_bytes));

  const auto version = get<std::uint32_t>(b + at_version);
  const bool header_intact = io::detail::crc32c(b, at_header_crc) == get<std::uint32_t>(b + at_header_crc);
  if (version != index_format_version)
    fail("format version " + std::to_string(version) + ": this kdspace reads version " +
         std::to_string(index_format_version) + (header_intact ? "" : " (or the header is damaged)"));
  if (!header_intact) fail("header checksum mismatch: the file is damaged");
  const auto mark = get<std::uint32_t>(b + at_byte_order);
  if (mark != byte_order_mark)
    fail("byte order mark " + hex(mark) + ": written on a machine of another byte order");

  const auto kind = get<std::uint32_t>(b + at_kind);
  const auto scalar = get<std::uint32_t>(b + at_scalar);
  const auto metric = get<std::uint32_t>(b + at_metric);
  if (!known_kind(kind)) fail("unknown index kind " + std::to_string(kind) + " (a newer kdspace wrote it?)");
  if (scalar > 2) fail("unknown scalar type " + std::to_string(scalar));
  if (metric > 4) fail("unknown metric " + std::to_string(metric));
  info_.kind = static_cast<IndexKind>(kind);
  info_.scalar = static_cast<ScalarType>(scalar);
  info_.metric = static_cast<MetricId>(metric);
  info_.dim = get<std::uint64_t>(b + at_dim);
  info_.count = get<std::uint64_t>(b + at_count);
  info_.file_bytes = get<std::uint64_t>(b + at_file_bytes);
  if (info_.file_bytes > size_)
    fail("truncated: the header says " + std::to_string(info_.file_bytes) + " bytes, the file has " +
         std::to_string(size_));
  if (info_.file_bytes < size_)
    fail("the file has " + std::to_string(size_) + " bytes, its header says " +
         std::to_string(info_.file_bytes) + " (extra bytes at the end)");

  const auto sections = get<std::uint32_t>(b + at_sections);
  if (sections > max_sections)
    fail("the header lists " + std::to_string(sections) + " sections (at most " +
         std::to_string(max_sections) + ")");
  const std::uint64_t table_end = index_header_bytes + std::uint64_t{sections} * index_section_entry_bytes;
  if (table_end > size_) fail("truncated: the section table runs past the end of the file");
  if (io::detail::crc32c(b + index_header_bytes, static_cast<std::size_t>(table_end - index_header_bytes)) !=
      get<std::uint32_t>(b + at_table_crc))
    fail("section table checksum mismatch: the file is damaged");

  info_.sections.clear();
  for (std::uint32_t i = 0; i < sections; ++i) {
    const unsigned char* e = b + index_header_bytes + std::size_t{i} * index_section_entry_bytes;
    SectionEntry s;
    s.type = static_cast<SectionType>(get<std::uint32_t>(e));
    s.part = get<std::uint32_t>(e + 4);
    s.version = get<std::uint32_t>(e + 8);
    s.item_bytes = get<std::uint32_t>(e + 12);
    s.offset = get<std::uint64_t>(e + 16);
    s.length = get<std::uint64_t>(e + 24);
    s.crc = get<std::uint32_t>(e + 32);
    const std::string where = "section " + std::to_string(i + 1) + " of the table";
    if (get<std::uint32_t>(e + 36) != 0) fail(where + ": reserved field is not 0");
    if (s.offset % index_section_alignment != 0 || s.offset < table_end || s.offset > size_ ||
        s.length > size_ - s.offset)
      fail(where + ": " + std::to_string(s.length) + " bytes at offset " + std::to_string(s.offset) +
           " do not lie inside the file's " + std::to_string(size_) +
           " bytes past its table, 64-byte aligned");
    if (s.item_bytes == 0 || s.length % s.item_bytes != 0)
      fail(where + ": length " + std::to_string(s.length) + " is not a whole number of " +
           std::to_string(s.item_bytes) + "-byte items");
    for (const SectionEntry& other : info_.sections)
      if (other.type == s.type && other.part == s.part) fail(where + ": " + describe(s) + " appears twice");
    info_.sections.push_back(s);
  }

  // Sections apart, and every byte outside them zero: no byte of the file goes unchecked.
  std::vector<SectionEntry> by_offset = info_.sections;
  std::sort(by_offset.begin(), by_offset.end(),
            [](const SectionEntry& x, const SectionEntry& y) { return x.offset < y.offset; });
  std::uint64_t covered = table_end;
  auto check_gap = [&](std::uint64_t end) {
    for (std::uint64_t at = covered; at < end; ++at)
      if (b[at] != 0) fail("byte " + std::to_string(at) + " between sections is not 0: the file is damaged");
  };
  for (const SectionEntry& s : by_offset) {
    if (s.offset < covered) fail(describe(s) + " overlaps the section before it");
    check_gap(s.offset);
    covered = s.offset + s.length;
  }
  check_gap(size_);

  if (checksums == Checksums::now) verify_checksums();
}

void IndexFile::verify_checksums() const {
  ChecksumPass pass(*this);
  pass.run();
  pass.finish();
}

// Chunks of 256 KiB: a few dozen per megabytes-large file, so that two threads finish within a chunk
// of each other, each chunk long enough that its combine (a few thousand instructions) is noise.
constexpr std::uint64_t checksum_chunk_bytes = std::uint64_t{1} << 18;

IndexFile::ChecksumPass::ChecksumPass(const IndexFile& file, std::vector<const SectionEntry*> streamed)
    : file_(file) {
  for (const SectionEntry* s : streamed) streamed_.push_back({s, {}});  // null: a section not there
  const std::vector<SectionEntry>& sections = file.info_.sections;
  for (std::size_t i = 0; i < sections.size(); ++i) {
    const bool is_streamed = std::any_of(streamed_.begin(), streamed_.end(),
                                         [&](const Streamed& s) { return s.section == &sections[i]; });
    if (is_streamed) continue;
    std::uint64_t at = 0;
    do {
      const std::uint64_t length = std::min(checksum_chunk_bytes, sections[i].length - at);
      chunks_.push_back({i, sections[i].offset + at, length});
      at += length;
    } while (at < sections[i].length);
  }
  crcs_.resize(chunks_.size());
  for (std::size_t k = 0; k < streamed_.size(); ++k) pieces(k, {0});
}

std::size_t IndexFile::ChecksumPass::run() {
  std::size_t taken = 0;
  for (std::size_t c = next_++; c < chunks_.size(); c = next_++, ++taken)
    crcs_[c] =
        io::detail::crc32c(file_.bytes_ + chunks_[c].offset, static_cast<std::size_t>(chunks_[c].length));
  return taken;
}

void IndexFile::ChecksumPass::pieces(std::size_t k, const std::vector<std::uint64_t>& starts) {
  if (k >= streamed_.size() || !streamed_[k].section) return;
  Streamed& s = streamed_[k];
  const std::uint64_t length = s.section->length;
  s.streams.assign(std::max<std::size_t>(starts.size(), 1), Stream{});
  std::uint64_t begin = 0;
  for (std::size_t p = 0; p < s.streams.size(); ++p) {
    const std::uint64_t end = p + 1 < starts.size() ? std::clamp(starts[p + 1], begin, length) : length;
    s.streams[p].begin = s.streams[p].done = begin;
    s.streams[p].end = end;
    begin = end;
  }
}

// A stream runs this far ahead of the reads it serves: 12 KiB, enough for the CRC's fast loops (three
// 4 KiB streams, or folding) and well inside the first-level cache, where the walk then finds them.
constexpr std::uint64_t stream_step_bytes = 3 * 4096;

std::uint64_t IndexFile::ChecksumPass::stream(std::size_t k, std::size_t piece, std::uint64_t end) {
  if (k >= streamed_.size() || !streamed_[k].section || piece >= streamed_[k].streams.size()) return end;
  const SectionEntry& section = *streamed_[k].section;
  Stream& s = streamed_[k].streams[piece];
  if (end <= s.done) return s.done;
  const std::uint64_t to = std::min(s.end, std::max(end, s.done + stream_step_bytes));
  s.crc = io::detail::crc32c_extend(s.crc, file_.bytes_ + section.offset + s.done,
                                    static_cast<std::size_t>(to - s.done));
  s.done = to;
  // No prefetch of the next step: the reads run front to back, which the processor's own prefetcher
  // follows. Asking for each of the step's cache lines as well (a prefetch every 64 bytes) made a
  // one-thread load of 1e6 3-D points 6-8% slower.
  return to;
}

void IndexFile::ChecksumPass::finish() {
  run();  // whatever chunks are left (none, when every thread ran run() to its end)
  const std::vector<SectionEntry>& sections = file_.info_.sections;
  std::size_t c = 0;
  for (std::size_t i = 0; i < sections.size(); ++i) {
    std::uint32_t crc = 0;
    const auto streamed = std::find_if(streamed_.begin(), streamed_.end(),
                                       [&](const Streamed& s) { return s.section == &sections[i]; });
    if (streamed != streamed_.end()) {
      const auto k = static_cast<std::size_t>(streamed - streamed_.begin());
      for (std::size_t p = 0; p < streamed->streams.size(); ++p) {
        const Stream& piece = streamed->streams[p];
        stream(k, p, piece.end);
        crc = p == 0 ? piece.crc
                     : io::detail::crc32c_combine(crc, piece.crc,
                                                  static_cast<std::size_t>(piece.end - piece.begin));
      }
    } else {
      crc = crcs_[c++];
      for (; c < chunks_.size() && chunks_[c].section == i; ++c)
        crc = io::detail::crc32c_combine(crc, crcs_[c], static_cast<std::size_t>(chunks_[c].length));
    }
    if (crc != sections[i].crc)
      file_.fail(file_.describe(sections[i]) + ": checksum mismatch: the file is damaged");
  }
}

std::vector<const SectionEntry*> SectionChecksums::sections_of(const std::vector<Reader>& readers) {
  std::vector<const SectionEntry*> sections;
  for (const Reader& r : readers) sections.push_back(r.section);
  return sections;
}

SectionChecksums::SectionChecksums(const IndexFile& file, const std::vector<Reader>& readers)
    : readers_(readers), pass_(file, sections_of(readers)) {}

// ---- checksums pending after a load ----------------------------------------------------------------------

PendingChecksums::~PendingChecksums() {
  if (thread_) thread_->join();
}

void PendingChecksums::start(const std::shared_ptr<const IndexFile>& file, bool own_thread) {
  if (pass_) throw std::logic_error("PendingChecksums::start called twice");
  file_ = file;
  pass_ = std::make_unique<IndexFile::ChecksumPass>(*file);
  if (!own_thread) return;
  try {
    thread_ = std::make_unique<kdspace::detail::SectionThread>([this] {
      pass_->run();
      thread_done_at_ = std::chrono::steady_clock::now();
    });
  } catch (const std::system_error&) {
    // No thread to be had: wait() takes them all.
  }
}

void PendingChecksums::wait() {
  if (!pass_ || waited_) {
    if (error_) std::rethrow_exception(error_);
    return;
  }
  waited_ = true;
  const bool helped = pass_->run() > 0;  // a share of what the thread has not taken yet
  const auto helped_until = std::chrono::steady_clock::now();
  if (thread_) thread_->finish();
  done_at_ = !thread_ ? helped_until : helped ? std::max(helped_until, thread_done_at_) : thread_done_at_;
  try {
    pass_->finish();  // the judgement (every chunk is taken)
  } catch (...) {
    error_ = std::current_exception();
  }
  if (error_) std::rethrow_exception(error_);
}

void SectionChecksums::pieces(std::size_t array, const std::vector<std::size_t>& starts) {
  for (std::size_t k = 0; k < readers_.size(); ++k)
    if (readers_[k].array == array) {
      std::vector<std::uint64_t> bytes(starts.size());
      for (std::size_t p = 0; p < starts.size(); ++p)
        bytes[p] = std::uint64_t{starts[p]} * readers_[k].item_bytes;
      pass_.pieces(k, bytes);
    }
}

std::size_t SectionChecksums::ready(std::size_t array, std::size_t piece, std::size_t end) {
  // The least of what the array's sections have ready (each runs a step ahead of `end`).
  std::size_t ready_to = std::numeric_limits<std::size_t>::max();
  for (std::size_t k = 0; k < readers_.size(); ++k)
    if (readers_[k].array == array && readers_[k].section) {
      const std::uint64_t done = pass_.stream(k, piece, std::uint64_t{end} * readers_[k].item_bytes);
      ready_to = std::min(ready_to, static_cast<std::size_t>(done / readers_[k].item_bytes));
    }
  return ready_to == std::numeric_limits<std::size_t>::max() ? end : ready_to;
}

const SectionEntry* IndexFile::find(SectionType type, std::uint32_t part) const {
  for (const SectionEntry& s : info_.sections)
    if (s.type == type && s.part == part) return &s;
  return nullptr;
}

const SectionEntry& IndexFile::section(SectionType type, std::uint32_t part, std::uint32_t version,
                                       std::size_t item_bytes, std::size_t count) const {
  const SectionEntry* s = find(type, part);
  if (!s)
    fail(std::string("no section '") + name_of(type) + "'" +
         (part ? " for part " + std::to_string(part) : "") + " in this " + name_of(info_.kind));
  if (s->version != version)
    fail(describe(*s) + ": layout version " + std::to_string(s->version) + ", this kdspace reads version " +
         std::to_string(version));
  if (s->item_bytes != item_bytes)
    fail(describe(*s) + ": items of " + std::to_string(s->item_bytes) + " bytes, expected " +
         std::to_string(item_bytes));
  if (count != any_count && s->length / item_bytes != count)
    fail(describe(*s) + ": " + std::to_string(s->length / item_bytes) + " items, expected " +
         std::to_string(count));
  return *s;
}

std::vector<std::uint64_t> IndexFile::words(SectionType type, std::uint32_t part, std::uint32_t version,
                                            std::size_t min_words) const {
  const kdspace::detail::Storage<std::uint64_t> w = array<std::uint64_t>(type, part, version);
  if (w.size() < min_words)
    fail(describe(*find(type, part)) + ": " + std::to_string(w.size()) + " words, expected at least " +
         std::to_string(min_words));
  return std::vector<std::uint64_t>(w.begin(), w.end());
}

// ---- writing -----------------------------------------------------------------------------------------

IndexWriter::IndexWriter(IndexKind kind, ScalarType scalar, MetricId metric, std::uint64_t dim,
                         std::uint64_t count) {
  info_.kind = kind;
  info_.scalar = scalar;
  info_.metric = metric;
  info_.dim = dim;
  info_.count = count;
}

void IndexWriter::add_bytes(SectionType type, std::uint32_t part, std::uint32_t version,
                            std::size_t item_bytes, const void* data, std::size_t bytes) {
  Pending p;
  p.entry.type = type;
  p.entry.part = part;
  p.entry.version = version;
  p.entry.item_bytes = static_cast<std::uint32_t>(item_bytes);
  p.entry.length = bytes;
  p.data = data;
  pending_.push_back(p);
}

const void* IndexWriter::keep(const void* data, std::size_t bytes) {
  const auto* p = static_cast<const unsigned char*>(data);
  kept_.push_back(std::make_unique<std::vector<unsigned char>>(p, p + bytes));
  return kept_.back()->data();
}

std::vector<unsigned char> IndexWriter::head() const {
  const std::size_t sections = pending_.size();
  if (sections > max_sections)
    throw Error("an index of more than " + std::to_string(max_sections) + " sections");
  const std::uint64_t table_end = index_header_bytes + sections * index_section_entry_bytes;
  std::vector<unsigned char> h(static_cast<std::size_t>(table_end), 0);
  std::uint64_t offset = table_end;
  for (std::size_t i = 0; i < sections; ++i) {
    SectionEntry e = pending_[i].entry;
    e.offset = offset = align_up(offset);
    e.crc = io::detail::crc32c(pending_[i].data, static_cast<std::size_t>(e.length));
    offset += e.length;
    unsigned char* p = h.data() + index_header_bytes + i * index_section_entry_bytes;
    put(p, static_cast<std::uint32_t>(e.type));
    put(p + 4, e.part);
    put(p + 8, e.version);
    put(p + 12, e.item_bytes);
    put(p + 16, e.offset);
    put(p + 24, e.length);
    put(p + 32, e.crc);
  }
  std::memcpy(h.data(), magic, sizeof magic);
  put(h.data() + at_version, index_format_version);
  put(h.data() + at_byte_order, byte_order_mark);
  put(h.data() + at_kind, static_cast<std::uint32_t>(info_.kind));
  put(h.data() + at_scalar, static_cast<std::uint32_t>(info_.scalar));
  put(h.data() + at_metric, static_cast<std::uint32_t>(info_.metric));
  put(h.data() + at_sections, static_cast<std::uint32_t>(sections));
  put(h.data() + at_dim, info_.dim);
  put(h.data() + at_count, info_.count);
  put(h.data() + at_file_bytes, offset);
  put(h.data() + at_table_crc, io::detail::crc32c(h.data() + index_header_bytes,
                                                  static_cast<std::size_t>(table_end - index_header_bytes)));
  put(h.data() + at_header_crc, io::detail::crc32c(h.data(), at_header_crc));
  return h;
}

std::vector<unsigned char> IndexWriter::bytes() const {
  std::vector<unsigned char> out = head();
  for (const Pending& p : pending_) {
    out.resize(static_cast<std::size_t>(align_up(out.size())), 0);
    const auto* data = static_cast<const unsigned char*>(p.data);
    out.insert(out.end(), data, data + p.entry.length);
  }
  return out;
}

void IndexWriter::write(const std::string& path) const {
  const std::vector<unsigned char> h = head();
  const std::filesystem::path target(path);
  const std::string folder = target.has_parent_path() ? target.parent_path().string() : std::string(".");

  // A name of our own beside the target: O_EXCL makes sure no one else's file is overwritten.
  static std::atomic<unsigned> counter{0};
  std::string temp;
  Fd out;
  for (int attempt = 0; out.fd < 0; ++attempt) {
    temp = path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
    out.fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (out.fd < 0 && (errno != EEXIST || attempt > 100))
      fail_path(path, "cannot save: cannot create " + temp + ": " + errno_text());
  }
  try {
    static const unsigned char zeros[index_section_alignment] = {};
    std::vector<iovec> pieces{{const_cast<unsigned char*>(h.data()), h.size()}};
    std::uint64_t offset = h.size();
    for (const Pending& p : pending_) {
      const std::uint64_t start = align_up(offset);
      if (start > offset) pieces.push_back({const_cast<unsigned char*>(zeros), static_cast<std::size_t>(start - offset)});
      if (p.entry.length > 0)
        pieces.push_back({const_cast<void*>(p.data), static_cast<std::size_t>(p.entry.length)});
      offset = start + p.entry.length;
    }
    write_all(out.fd, std::move(pieces));
    if (::fsync(out.fd) != 0) throw std::system_error(errno, std::generic_category());
    const int fd = out.fd;
    out.fd = -1;
    if (::close(fd) != 0) throw std::system_error(errno, std::generic_category());
  } catch (const std::system_error& e) {
    ::unlink(temp.c_str());
    fail_path(path, "cannot save: writing " + temp + " failed: " + e.code().message() +
                        " (the old file, if any, is unchanged)");
  }
  if (::rename(temp.c_str(), path.c_str()) != 0) {
    const std::string why = errno_text();
    ::unlink(temp.c_str());
    fail_path(path, "cannot save: cannot rename " + temp + " to it: " + why);
  }
  // The rename is durable once the folder is on disk too.
  Fd dir{::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)};
  if (dir.fd >= 0) ::fsync(dir.fd);
}

// ---- resealing -----------------------------------------------------------------------------------------

void reseal_index_bytes(std::vector<unsigned char>& bytes) {
  if (bytes.size() < index_header_bytes || std::memcmp(bytes.data(), magic, sizeof magic) != 0) return;
  unsigned char* b = bytes.data();
  const auto sections = get<std::uint32_t>(b + at_sections);
  if (sections > max_sections) return;
  const std::uint64_t table_end = index_header_bytes + std::uint64_t{sections} * index_section_entry_bytes;
  if (table_end > bytes.size()) return;
  for (std::uint32_t i = 0; i < sections; ++i) {
    unsigned char* e = b + index_header_bytes + std::size_t{i} * index_section_entry_bytes;
    const auto offset = get<std::uint64_t>(e + 16), length = get<std::uint64_t>(e + 24);
    if (offset <= bytes.size() && length <= bytes.size() - offset)
      put(e + 32, io::detail::crc32c(b + offset, static_cast<std::size_t>(length)));
  }
  put(b + at_table_crc,
      io::detail::crc32c(b + index_header_bytes, static_cast<std::size_t>(table_end - index_header_bytes)));
  put(b + at_header_crc, io::detail::crc32c(b, at_header_crc));
}

}  // namespace kdspace::io
