#include "pipeline/io/text_header_check.h"

#include "core/errors.h"

#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

constexpr std::size_t kMaxHeaderBytes = 1 << 20;

[[noreturn]] void layout(const fs::path& p, const std::string& what, const std::string& hint = "the header is corrupt") {
  throw InputError(ExitCode::unsupported_input, what, p, hint);
}

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string trim(const std::string& s) {
  std::size_t a = 0, b = s.size();
  while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
  while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
  return s.substr(a, b - a);
}

/// Every number of `s` (separators: spaces, commas, parentheses); false when a word is not one.
bool numbers(const std::string& s, std::vector<double>& out) {
  std::string t = s;
  for (char& c : t)
    if (c == ',' || c == '(' || c == ')') c = ' ';
  std::istringstream in(t);
  std::string w;
  while (in >> w) {
    char* end = nullptr;
    const double v = std::strtod(w.c_str(), &end);
    if (end == w.c_str() || *end != '\0') return false;
    out.push_back(v);
  }
  return true;
}

std::vector<std::int64_t> sizes_of(const fs::path& p, const std::string& field, const std::string& value) {
  std::vector<double> v;
  if (!numbers(value, v) || v.empty()) layout(p, field + " '" + value + "' is not a list of whole numbers");
  std::vector<std::int64_t> out;
  for (double d : v) {
    if (!(d >= 1.0) || d != std::floor(d) || d > 1e9)
      layout(p, field + " '" + value + "': every size must be a whole number of at least 1");
    out.push_back(std::int64_t(d));
  }
  return out;
}

/// Bytes of the data that follow `offset` in `file` (raw) or that its zlib/gzip stream inflates
/// to (`compressed`), read through to the end of the stream; throws 11 when the stream is cut.
std::uint64_t data_bytes(const fs::path& header, const fs::path& file, std::uint64_t offset, bool compressed) {
  std::error_code ec;
  const std::uint64_t size = fs::file_size(file, ec);
  if (ec)
    throw InputError(ExitCode::input_not_found, "its data file " + file.string() + " cannot be read", header,
                     "keep the data file beside its header");
  if (offset > size) throw InputError(ExitCode::corrupt_file, "the header runs past the end of the file", header, "copy it again");
  if (!compressed) return size - offset;
  std::ifstream in(file, std::ios::binary);
  in.seekg(std::streamoff(offset));
  z_stream z{};
  if (inflateInit2(&z, 15 + 32) != Z_OK) throw InputError(ExitCode::corrupt_file, "cannot inflate its data", header, "");
  std::vector<unsigned char> src(1 << 16), dst(1 << 16);
  std::uint64_t total = 0;
  int rc = Z_OK;
  while (rc != Z_STREAM_END) {
    if (z.avail_in == 0) {
      in.read(reinterpret_cast<char*>(src.data()), std::streamsize(src.size()));
      const std::streamsize n = in.gcount();
      if (n <= 0) break;
      z.next_in = src.data();
      z.avail_in = unsigned(n);
    }
    z.next_out = dst.data();
    z.avail_out = unsigned(dst.size());
    rc = inflate(&z, Z_NO_FLUSH);
    if (rc != Z_OK && rc != Z_STREAM_END && rc != Z_BUF_ERROR) break;
    total += dst.size() - z.avail_out;
    if (rc == Z_BUF_ERROR && z.avail_in == 0 && !in) break;
  }
  inflateEnd(&z);
  if (rc != Z_STREAM_END)
    throw InputError(ExitCode::corrupt_file, "its compressed data are cut off or corrupt", header,
                     "copy the file again; the compressed stream must be whole");
  return total;
}

void check_sizes_memory_and_data(const fs::path& header, std::vector<std::int64_t> sizes, int bytes,
                                 std::uint64_t available, std::int64_t budget) {
  while (sizes.size() < 3) sizes.push_back(1);
  for (std::size_t d = 3; d < sizes.size(); ++d)
    if (sizes[d] > 1)
      layout(header, "a " + std::to_string(sizes.size()) + "-D image (size " + std::to_string(sizes[d]) + " along axis " +
                         std::to_string(d + 1) + ")",
             "give one 3-D volume of scalar voxels");
  const double voxels = double(sizes[0]) * double(sizes[1]) * double(sizes[2]);
  const double needed = voxels * double(4 + bytes);
  if (budget > 0 && needed > double(budget))
    throw InputError(ExitCode::too_large,
                     "reading it needs " + std::to_string(std::int64_t(needed / 1048576.0)) + " MiB, more than the budget of " +
                         std::to_string(budget >> 20) + " MiB",
                     header, "raise --max-memory-mb ([ingest] max_memory_mb) or crop the volume");
  const double data = voxels * double(bytes);
  if (double(available) < data)
    throw InputError(ExitCode::corrupt_file,
                     "the header announces " + std::to_string(sizes[0]) + " × " + std::to_string(sizes[1]) + " × " +
                         std::to_string(sizes[2]) + " voxels (" + std::to_string(std::uint64_t(data)) +
                         " bytes) but the file holds " + std::to_string(available) + " bytes of data",
                     header, "the file is truncated or its header is wrong; copy it again");
}

void check_geometry(const fs::path& p, const std::string& field, const std::vector<double>& v, bool positive) {
  for (double x : v)
    if (!std::isfinite(x) || (positive && !(x > 0.0)))
      throw GeometryError(field + " holds " + (std::isfinite(x) ? "a value that is not positive" : "a value that is not finite"),
                          p, "the header's geometry is corrupt");
}

void check_axes(const fs::path& p, const std::string& field, const std::vector<double>& m, std::size_t n) {
  check_geometry(p, field, m, false);
  if (n == 3 && m.size() == 9) {
    const double det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6]);
    if (!(std::abs(det) > 1e-12)) throw GeometryError(field + " is singular (its axes are not independent)", p, "the header's orientation is corrupt");
  }
}

/// The text header: lines up to the first empty one (NRRD) or through ElementDataFile (MetaImage).
std::vector<std::string> header_lines(const fs::path& p, bool metaimage, std::uint64_t& data_offset) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw InputError(ExitCode::input_not_found, "cannot open the file", p, "check the path and permissions");
  std::vector<std::string> lines;
  std::string line;
  std::uint64_t pos = 0;
  while (std::getline(in, line)) {
    pos += line.size() + 1;
    if (pos > kMaxHeaderBytes) layout(p, "no end of the text header within its first MiB");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!metaimage && line.empty()) break;
    lines.push_back(line);
    if (metaimage && lower(trim(line.substr(0, line.find('=')))) == "elementdatafile") break;
  }
  data_offset = pos;
  return lines;
}

int type_bytes(const std::string& t) {
  static const std::map<std::string, int> kinds = {
      {"signed char", 1}, {"int8", 1}, {"int8_t", 1}, {"uchar", 1}, {"unsigned char", 1}, {"uint8", 1}, {"uint8_t", 1},
      {"short", 2}, {"short int", 2}, {"signed short", 2}, {"signed short int", 2}, {"int16", 2}, {"int16_t", 2},
      {"ushort", 2}, {"unsigned short", 2}, {"unsigned short int", 2}, {"uint16", 2}, {"uint16_t", 2},
      {"int", 4}, {"signed int", 4}, {"int32", 4}, {"int32_t", 4}, {"uint", 4}, {"unsigned int", 4}, {"uint32", 4},
      {"uint32_t", 4}, {"longlong", 8}, {"long long", 8}, {"long long int", 8}, {"signed long long", 8},
      {"signed long long int", 8}, {"int64", 8}, {"int64_t", 8}, {"ulonglong", 8}, {"unsigned long long", 8},
      {"unsigned long long int", 8}, {"uint64", 8}, {"uint64_t", 8}, {"float", 4}, {"double", 8},
      // MetaImage
      {"met_char", 1}, {"met_uchar", 1}, {"met_short", 2}, {"met_ushort", 2}, {"met_int", 4}, {"met_uint", 4},
      {"met_long", 4}, {"met_ulong", 4}, {"met_long_long", 8}, {"met_ulong_long", 8}, {"met_float", 4}, {"met_double", 8}};
  const auto it = kinds.find(lower(trim(t)));
  return it == kinds.end() ? 0 : it->second;
}

}  // namespace

void check_nrrd_file(const fs::path& p, std::int64_t budget) {
  std::uint64_t offset = 0;
  const std::vector<std::string> lines = header_lines(p, false, offset);
  if (lines.empty() || lines[0].rfind("NRRD000", 0) != 0) layout(p, "not an NRRD file (no NRRD000x magic line)");
  std::map<std::string, std::string> f;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    if (lines[i].empty() || lines[i][0] == '#') continue;
    const std::size_t c = lines[i].find(':');
    if (c == std::string::npos) layout(p, "header line " + std::to_string(i + 1) + " '" + lines[i] + "' is no field");
    const bool key_value = c + 1 < lines[i].size() && lines[i][c + 1] == '=';
    if (key_value) continue;  // key:=value pairs carry no geometry
    f[lower(trim(lines[i].substr(0, c)))] = trim(lines[i].substr(c + 1));
  }
  auto need = [&](const char* k) {
    if (!f.count(k)) layout(p, std::string("the header has no '") + k + "' field");
    return f[k];
  };
  std::vector<double> dim;
  if (!numbers(need("dimension"), dim) || dim.size() != 1 || !(dim[0] >= 1 && dim[0] <= 16) || dim[0] != std::floor(dim[0]))
    layout(p, "dimension '" + f["dimension"] + "' is not a whole number from 1 to 16");
  const std::size_t n = std::size_t(dim[0]);
  const std::vector<std::int64_t> sizes = sizes_of(p, "sizes", need("sizes"));
  if (sizes.size() != n) layout(p, "sizes lists " + std::to_string(sizes.size()) + " sizes for " + std::to_string(n) + " dimensions");
  const int bytes = type_bytes(need("type"));
  if (bytes == 0) layout(p, "voxels of type '" + f["type"] + "' are not CT numbers", "give a scalar image (integer or real voxels)");
  if (f.count("kinds")) {
    std::istringstream k(f["kinds"]);
    std::string w;
    while (k >> w)
      if (const std::string l = lower(w); l != "domain" && l != "space" && l != "time" && l != "none" && l != "???")
        layout(p, "an axis of kind '" + w + "' (more than one component per voxel)", "give a scalar image");
  }
  if (f.count("space directions")) {
    std::string s = f["space directions"];
    std::vector<double> m;
    std::string cleaned;
    std::istringstream in(s);
    std::string w;
    while (in >> w)
      if (lower(w) != "none") cleaned += w + " ";
    if (!numbers(cleaned, m)) layout(p, "space directions '" + s + "' are not vectors of numbers");
    check_axes(p, "space directions", m, std::min<std::size_t>(n, 3));
    for (std::size_t a = 0; a + 2 < m.size(); a += 3)
      if (!(std::hypot(m[a], m[a + 1], m[a + 2]) > 0))
        throw GeometryError("space directions hold a zero vector (no spacing along an axis)", p, "the header's geometry is corrupt");
  }
  if (f.count("spacings")) {
    std::vector<double> s;
    std::string cleaned;
    std::istringstream in(f["spacings"]);
    std::string w;
    while (in >> w)
      if (lower(w) != "nan" || n <= 3) cleaned += w + " ";
    if (!numbers(cleaned, s)) layout(p, "spacings '" + f["spacings"] + "' are not numbers");
    check_geometry(p, "spacings", s, true);
  }
  if (f.count("space origin")) {
    std::vector<double> o;
    if (!numbers(f["space origin"], o)) layout(p, "space origin '" + f["space origin"] + "' is not a vector of numbers");
    check_geometry(p, "space origin", o, false);
  }
  const std::string enc = lower(need("encoding"));
  fs::path data = p;
  std::uint64_t data_offset = offset;
  const std::string detached = f.count("data file") ? f["data file"] : f.count("datafile") ? f["datafile"] : "";
  if (!detached.empty()) {
    if (lower(detached).rfind("list", 0) == 0 || detached.find(' ') != std::string::npos)
      layout(p, "data in several files ('data file: " + detached + "')", "give one data file");
    data = p.parent_path() / detached;
    data_offset = 0;
  }
  std::uint64_t available = 0;
  if (enc == "raw") available = data_bytes(p, data, data_offset, false);
  else if (enc == "gzip" || enc == "gz") available = data_bytes(p, data, data_offset, true);
  else if (enc == "ascii" || enc == "text" || enc == "txt") available = std::uint64_t(-1);  // length not known in advance
  else layout(p, "encoding '" + enc + "' is not read here", "write the volume raw or gzip-compressed");
  check_sizes_memory_and_data(p, sizes, bytes, available, budget);
}

void check_metaimage_file(const fs::path& p, std::int64_t budget) {
  std::uint64_t offset = 0;
  const std::vector<std::string> lines = header_lines(p, true, offset);
  std::map<std::string, std::string> f;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::size_t e = lines[i].find('=');
    if (e == std::string::npos) {
      if (trim(lines[i]).empty()) continue;
      layout(p, "header line " + std::to_string(i + 1) + " '" + lines[i] + "' is no 'Key = Value' field");
    }
    f[lower(trim(lines[i].substr(0, e)))] = trim(lines[i].substr(e + 1));
  }
  auto need = [&](const char* k) {
    if (!f.count(k)) layout(p, std::string("the header has no '") + k + "' field");
    return f[k];
  };
  std::vector<double> nd;
  if (!numbers(need("ndims"), nd) || nd.size() != 1 || !(nd[0] >= 1 && nd[0] <= 16) || nd[0] != std::floor(nd[0]))
    layout(p, "NDims '" + f["ndims"] + "' is not a whole number from 1 to 16");
  const std::size_t n = std::size_t(nd[0]);
  const std::vector<std::int64_t> sizes = sizes_of(p, "DimSize", need("dimsize"));
  if (sizes.size() != n) layout(p, "DimSize lists " + std::to_string(sizes.size()) + " sizes for NDims = " + std::to_string(n));
  if (f.count("elementnumberofchannels") && trim(f["elementnumberofchannels"]) != "1")
    layout(p, "ElementNumberOfChannels = " + f["elementnumberofchannels"] + " (more than one component per voxel)",
           "give a scalar image");
  const int bytes = type_bytes(need("elementtype"));
  if (bytes == 0) layout(p, "voxels of type '" + f["elementtype"] + "' are not CT numbers", "give a scalar image (integer or real voxels)");
  for (const char* k : {"elementspacing", "elementsize"})
    if (f.count(k)) {
      std::vector<double> s;
      if (!numbers(f[k], s)) layout(p, std::string(k) + " '" + f[k] + "' is not a list of numbers");
      check_geometry(p, k == std::string("elementspacing") ? "ElementSpacing" : "ElementSize", s, true);
    }
  for (const char* k : {"transformmatrix", "rotation", "orientation"})
    if (f.count(k)) {
      std::vector<double> m;
      if (!numbers(f[k], m)) layout(p, std::string(k) + " '" + f[k] + "' is not a list of numbers");
      check_axes(p, "TransformMatrix", m, n);
    }
  for (const char* k : {"offset", "position", "origin"})
    if (f.count(k)) {
      std::vector<double> o;
      if (!numbers(f[k], o)) layout(p, std::string(k) + " '" + f[k] + "' is not a list of numbers");
      check_geometry(p, "Offset", o, false);
    }
  const std::string file = need("elementdatafile");
  fs::path data = p;
  std::uint64_t data_offset = offset;
  if (lower(file) != "local") {
    if (lower(file).rfind("list", 0) == 0 || file.find('%') != std::string::npos || file.find(' ') != std::string::npos)
      layout(p, "data in several files (ElementDataFile = " + file + ")", "give one data file");
    data = p.parent_path() / file;
    data_offset = 0;
  }
  if (f.count("headersize") && trim(f["headersize"]) != "0" && lower(file) != "local")
    layout(p, "a HeaderSize before the data is not read here", "write the data file without a header of its own");
  const bool compressed = f.count("compresseddata") && lower(f["compresseddata"]) == "true";
  const bool binary = !f.count("binarydata") || lower(f["binarydata"]) == "true";
  const std::uint64_t available = binary ? data_bytes(p, data, data_offset, compressed) : std::uint64_t(-1);
  check_sizes_memory_and_data(p, sizes, bytes, available, budget);
}

}  // namespace organsmith
