// libFuzzer target: the case-file parser (pipeline/case/case_file.h: TOML, every [stages.*] option
// typed and range-checked, organs from the registry) on any text. It must return a case or
// throw organsmith's own error; never crash or hang.
#include "core/errors.h"
#include "pipeline/case/case_file.h"

#include <string>

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    (void)organsmith::parse_case(text, "/nonexistent/fuzz/case.toml");
  } catch (const organsmith::Error&) {
  }
  return 0;
}
