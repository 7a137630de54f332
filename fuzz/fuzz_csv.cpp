// libFuzzer target: the one CSV reader (core/csv.h, libcsv underneath) on any text. It must
// return a table whose rows all have the header's field count and increasing line numbers, or
// throw organsmith's own error; never crash or hang.
#include "core/csv.h"

#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const organsmith::CsvTable t = organsmith::parse_csv(text, "fuzz.csv", organsmith::ExitCode::calibration_data);
    int line = t.header.line;
    for (const auto& r : t.rows) {
      if (r.fields.size() != t.header.fields.size() || r.line < line) std::abort();
      line = r.line;
    }
  } catch (const organsmith::Error&) {
  }
  return 0;
}
