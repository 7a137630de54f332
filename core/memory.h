#pragma once
// Peak resident memory of this process, as the kernel counts it (Linux /proc), and the default
// memory budget of a decoded volume.

#include <cstdint>

namespace organsmith {

/// 60 % of the machine's physical memory: the budget for a decoded volume when none is given
/// (--max-memory-mb, [ingest] max_memory_mb).
std::int64_t default_memory_budget_bytes();

/// Resets the kernel's resident-set high-water mark so that the next peak_rss_mib() measures
/// from now. Returns false where the kernel does not allow it (the figure is then the process peak).
bool reset_peak_rss();

/// The resident-set high-water mark (VmHWM), MiB; 0 where it cannot be read.
double peak_rss_mib();

}  // namespace organsmith
