#include "pipeline/io/dicom_structure.h"

#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <vector>

namespace organsmith {

namespace {

constexpr std::uint32_t kUndefined = 0xffffffffu;
constexpr int kMaxDepth = 64;
constexpr std::uint64_t kMaxElements = 10'000'000;
constexpr std::uint64_t kMaxInflatedBytes = std::uint64_t(1) << 31;  // 2 GiB of inflated data set

struct Bad {
  std::string why;
};

std::string tag_text(std::uint16_t g, std::uint16_t e) {
  char b[16];
  std::snprintf(b, sizeof b, "(%04x,%04x)", g, e);
  return b;
}

bool long_form(const unsigned char* vr) {
  static const char* kinds[] = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ", "SV", "UC", "UN", "UR", "UT", "UV"};
  for (const char* k : kinds)
    if (vr[0] == k[0] && vr[1] == k[1]) return true;
  return false;
}

struct Header {
  std::uint16_t group = 0, element = 0;
  std::uint32_t length = 0;
  std::uint64_t size = 8;  // header bytes
  bool sq = false;         // explicit VR SQ
  bool un = false;         // explicit VR UN (of undefined length: an implicit-VR sequence inside)
};

class Walker {
 public:
  Walker(std::uint64_t size, const ByteReader& read, DicomStructure& out) : size_(size), read_(read), out_(out) {}

  bool explicit_vr = true, big = false;

  /// Element header at `pos` (tag, VR, length by the current syntax); Bad when it does not fit.
  Header header(std::uint64_t pos, bool meta = false) {
    unsigned char h[12];
    const std::size_t avail = std::size_t(std::min<std::uint64_t>(12, size_ - std::min(pos, size_)));
    if (avail < 8 || !read_(pos, avail, h)) throw Bad{"is truncated inside an element header at byte " + std::to_string(pos)};
    const bool be = big && !meta;
    auto u16 = [&](const unsigned char* p) { return be ? std::uint16_t(p[0] << 8 | p[1]) : std::uint16_t(p[0] | p[1] << 8); };
    auto u32 = [&](const unsigned char* p) {
      return be ? std::uint32_t(p[0]) << 24 | std::uint32_t(p[1]) << 16 | std::uint32_t(p[2]) << 8 | p[3]
                : std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 | std::uint32_t(p[3]) << 24;
    };
    Header r;
    r.group = u16(h);
    r.element = u16(h + 2);
    if (r.group == 0xfffe) {  // items and delimiters: tag and a 4-byte length in every syntax
      r.length = u32(h + 4);
    } else if (explicit_vr || meta) {
      if (long_form(h + 4)) {
        if (avail < 12) throw Bad{"is truncated inside an element header at byte " + std::to_string(pos)};
        r.length = u32(h + 8);
        r.size = 12;
        r.sq = h[4] == 'S' && h[5] == 'Q';
        r.un = h[4] == 'U' && h[5] == 'N';
      } else {
        r.length = u16(h + 6);
      }
    } else {
      r.length = u32(h + 4);
    }
    if (++count_ > kMaxElements) throw Bad{"holds more than 10 million data elements"};
    return r;
  }

  void fits(std::uint64_t pos, const Header& h, std::uint64_t end) {
    if (pos + h.size + h.length > end) {
      throw Bad{"is truncated: element " + tag_text(h.group, h.element) + " needs " + std::to_string(h.length) +
                " bytes but only " + std::to_string(end - std::min(end, pos + h.size)) + " remain"};
    }
  }

  /// Elements from `pos` to `end`; inside an item of undefined length until its delimiter.
  /// Returns the position after what was walked; `done` when the pixel data was reached.
  std::uint64_t dataset(std::uint64_t pos, std::uint64_t end, int depth, bool in_item, bool& done) {
    if (depth > kMaxDepth) throw Bad{"nests sequences deeper than " + std::to_string(kMaxDepth) + " levels"};
    while (pos < end) {
      const Header h = header(pos);
      if (h.group == 0xfffe && h.element == 0xe00d) {  // item delimiter
        if (in_item) return pos + 8;
        pos += 8;  // a stray delimiter: GDCM skips it too
        continue;
      }
      if (h.group == 0xfffe && (h.element == 0xe0dd || h.element == 0xe000)) {
        if (h.element == 0xe0dd || h.length == 0) {
          pos += 8;
          continue;
        }
        throw Bad{"has an item " + tag_text(h.group, h.element) + " outside any sequence at byte " + std::to_string(pos)};
      }
      const bool pixels = h.group == 0x7fe0 && h.element == 0x0010;
      if (h.length == kUndefined) {
        pos += h.size;
        if (pixels) {
          pos = fragments(pos, end, depth == 0);
          done = depth == 0;
          if (done) return pos;
          continue;
        }
        if (h.un) {
          // UN of undefined length holds a sequence encoded in implicit VR little endian.
          const bool e = explicit_vr, b = big;
          explicit_vr = false;
          big = false;
          pos = sequence(pos, end, depth + 1);
          explicit_vr = e;
          big = b;
        } else {
          pos = sequence(pos, end, depth + 1);
        }
        continue;
      }
      fits(pos, h, end);
      if (pixels && depth == 0) {
        out_.has_pixel_data = true;
        out_.encapsulated = false;
        out_.fragment_bytes = 0;
        out_.pixel_offset = pos + h.size;
        out_.pixel_bytes = h.length;
        done = true;
        return pos + h.size + h.length;
      }
      if (h.sq && h.length > 0) {
        // A sequence of defined length: its items must fill it exactly.
        const std::uint64_t inner_end = pos + h.size + h.length;
        std::uint64_t p = pos + h.size;
        while (p < inner_end) p = item(p, inner_end, depth + 1);
      }
      pos += h.size + h.length;
    }
    if (in_item) throw Bad{"is truncated inside a sequence item (no item delimiter before the end)"};
    return pos;
  }

  /// One item of a sequence at `pos`; returns the position after it.
  std::uint64_t item(std::uint64_t pos, std::uint64_t end, int depth) {
    const Header h = header(pos);
    if (h.group != 0xfffe || h.element != 0xe000)
      throw Bad{"has element " + tag_text(h.group, h.element) + " where a sequence item should be, at byte " +
                std::to_string(pos)};
    if (h.length == kUndefined) {
      bool done = false;
      return dataset(pos + 8, end, depth, true, done);
    }
    fits(pos, h, end);
    bool done = false;
    const std::uint64_t after = dataset(pos + 8, pos + 8 + h.length, depth, false, done);
    (void)after;
    return pos + 8 + h.length;
  }

  /// Items of a sequence of undefined length up to its delimiter.
  std::uint64_t sequence(std::uint64_t pos, std::uint64_t end, int depth) {
    if (depth > kMaxDepth) throw Bad{"nests sequences deeper than " + std::to_string(kMaxDepth) + " levels"};
    while (true) {
      if (pos >= end) throw Bad{"is truncated inside a sequence (no sequence delimiter before the end)"};
      const Header h = header(pos);
      if (h.group == 0xfffe && h.element == 0xe0dd) return pos + 8;
      pos = item(pos, end, depth);
    }
  }

  /// Encapsulated pixel data: fragments of defined length up to the sequence delimiter.
  std::uint64_t fragments(std::uint64_t pos, std::uint64_t end, bool image) {
    if (image) {  // not an icon's pixel data nested in a sequence
      out_.has_pixel_data = true;
      out_.encapsulated = true;
      out_.pixel_offset = pos;
      out_.pixel_bytes = 0;
    }
    while (true) {
      if (pos >= end) throw Bad{"is truncated inside its encapsulated pixel data (no sequence delimiter)"};
      const Header h = header(pos);
      if (h.group == 0xfffe && h.element == 0xe0dd) return pos + 8;
      if (h.group != 0xfffe || h.element != 0xe000 || h.length == kUndefined)
        throw Bad{"has malformed encapsulated pixel data at byte " + std::to_string(pos) + " (" +
                  tag_text(h.group, h.element) + " where a fragment should be)"};
      fits(pos, h, end);
      if (image) out_.fragment_bytes += h.length;
      pos += 8 + std::uint64_t(h.length);
    }
  }

  /// The file meta group (explicit VR little endian) from byte 132; returns where it ends.
  std::uint64_t meta(std::uint64_t pos) {
    while (pos < size_) {
      const Header h = header(pos, true);
      if (h.group != 0x0002) return pos;
      if (h.length == kUndefined) throw Bad{"has a file meta element " + tag_text(h.group, h.element) + " of undefined length"};
      fits(pos, h, size_);
      if (h.element == 0x0010 && h.length < 256) {
        std::string v(h.length, '\0');
        if (h.length > 0 && !read_(pos + h.size, h.length, reinterpret_cast<unsigned char*>(v.data())))
          throw Bad{"is truncated in its transfer syntax"};
        while (!v.empty() && (v.back() == '\0' || v.back() == ' ')) v.pop_back();
        out_.transfer_syntax = v;
      }
      pos += h.size + h.length;
    }
    return pos;
  }

 private:
  std::uint64_t size_;
  const ByteReader& read_;
  DicomStructure& out_;
  std::uint64_t count_ = 0;
};

/// Inflates a raw deflate stream (the data set of a deflated transfer syntax).
bool inflate_all(const ByteReader& read, std::uint64_t from, std::uint64_t size, std::vector<unsigned char>& out,
                 std::string& why) {
  z_stream z{};
  if (inflateInit2(&z, -15) != Z_OK) {
    why = "cannot start inflating its deflated data set";
    return false;
  }
  std::vector<unsigned char> in(1 << 16), buf(1 << 16);
  int rc = Z_OK;
  std::uint64_t pos = from;
  while (rc != Z_STREAM_END) {
    if (z.avail_in == 0) {
      if (pos >= size) break;
      const std::size_t n = std::size_t(std::min<std::uint64_t>(in.size(), size - pos));
      if (!read(pos, n, in.data())) break;
      pos += n;
      z.next_in = in.data();
      z.avail_in = unsigned(n);
    }
    z.next_out = buf.data();
    z.avail_out = unsigned(buf.size());
    rc = inflate(&z, Z_NO_FLUSH);
    if (rc != Z_OK && rc != Z_STREAM_END && rc != Z_BUF_ERROR) break;
    out.insert(out.end(), buf.data(), buf.data() + (buf.size() - z.avail_out));
    if (out.size() > kMaxInflatedBytes) {
      inflateEnd(&z);
      why = "inflates to more than 2 GiB";
      return false;
    }
    if (rc == Z_BUF_ERROR && z.avail_in == 0 && pos >= size) break;
  }
  inflateEnd(&z);
  if (rc != Z_STREAM_END) {
    why = "is truncated: its deflated data set is cut off or corrupt";
    return false;
  }
  return true;
}

}  // namespace

DicomStructure check_dicom_structure(std::uint64_t size, const ByteReader& read) {
  DicomStructure out;
  unsigned char magic[4];
  if (size < 132 || !read(128, 4, magic) || std::memcmp(magic, "DICM", 4) != 0) {
    out.why = "has no DICOM preamble";
    return out;
  }
  try {
    Walker w(size, read, out);
    const std::uint64_t data_start = w.meta(132);
    // A data set needs at least one element (GDCM asserts on a file that ends after its meta).
    if (size < data_start + 8) throw Bad{"holds no data set after its file meta information"};
    const std::string& ts = out.transfer_syntax;
    if (ts == "1.2.840.10008.1.2.1.99") {  // deflated explicit VR little endian
      std::vector<unsigned char> inflated;
      if (!inflate_all(read, data_start, size, inflated, out.why)) return out;
      const ByteReader mem = [&inflated](std::uint64_t pos, std::size_t n, unsigned char* dst) {
        if (pos > inflated.size() || n > inflated.size() - pos) return false;
        std::memcpy(dst, inflated.data() + pos, n);
        return true;
      };
      DicomStructure inner;
      Walker wi(inflated.size(), mem, inner);
      bool done = false;
      wi.dataset(0, inflated.size(), 0, false, done);
      out.has_pixel_data = inner.has_pixel_data;
      out.encapsulated = inner.encapsulated;
      out.pixel_offset = 0;  // an offset in the inflated stream, not in the file
      out.pixel_bytes = inner.pixel_bytes;
      out.fragment_bytes = inner.fragment_bytes;
      out.complete = true;
      return out;
    }
    if (ts.empty()) {
      // No transfer syntax: implicit VR has a length where explicit VR has two capital letters.
      unsigned char h[6];
      w.explicit_vr = data_start + 6 <= size && read(data_start, 6, h) && std::isupper(h[4]) && std::isupper(h[5]);
    } else {
      w.explicit_vr = ts != "1.2.840.10008.1.2";
      w.big = ts == "1.2.840.10008.1.2.2";
    }
    bool done = false;
    w.dataset(data_start, size, 0, false, done);
    out.complete = true;
  } catch (const Bad& b) {
    out.why = b.why;
    out.complete = false;
  }
  return out;
}

DicomStructure check_dicom_structure(const unsigned char* data, std::size_t size) {
  return check_dicom_structure(size, [data, size](std::uint64_t pos, std::size_t n, unsigned char* dst) {
    if (pos > size || n > size - pos) return false;
    if (n) std::memcpy(dst, data + pos, n);
    return true;
  });
}

DicomStructure check_dicom_structure(const std::filesystem::path& file) {
  std::error_code ec;
  const std::uint64_t size = std::filesystem::file_size(file, ec);
  if (ec) {
    DicomStructure out;
    out.why = "cannot be read (" + ec.message() + ")";
    return out;
  }
  std::ifstream in(file, std::ios::binary);
  return check_dicom_structure(size, [&in, size](std::uint64_t pos, std::size_t n, unsigned char* dst) {
    if (pos > size || n > size - pos) return false;
    in.clear();
    in.seekg(std::streamoff(pos));
    in.read(reinterpret_cast<char*>(dst), std::streamsize(n));
    return bool(in);
  });
}

}  // namespace organsmith
