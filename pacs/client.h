#pragma once
// Inside the PACS module: what pull_study() asks of a protocol. One implementation per protocol
// (dicomweb.cpp: libcurl; dimse.cpp: DCMTK); their library types stay in those files.

#include "core/progress.h"
#include "pacs/pacs.h"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace organsmith::pacs_detail {

/// Receives one instance as the bytes of a DICOM Part 10 file.
using StoreFn = std::function<void(std::string&& file_bytes)>;

class Client {
 public:
  virtual ~Client() = default;
  /// True when the PACS knows the study. Throws PacsError (unreachable, refused, …).
  virtual bool has_study(const std::string& study) = 0;
  /// SeriesInstanceUIDs of the study's series of modality CT.
  virtual std::vector<std::string> ct_series(const std::string& study) = 0;
  /// SOPInstanceUIDs of a series' instances (empty when the series is not there).
  virtual std::vector<std::string> instances(const std::string& study, const std::string& series) = 0;
  /// Retrieves instances of a series: the whole series when `sops` is empty, else those. Calls
  /// `store` for every instance received (also when the transfer is cut off later: what came
  /// whole is kept); throws PacsError(pacs_transfer) when the transfer broke off.
  virtual void retrieve(const std::string& study, const std::string& series, const std::vector<std::string>& sops,
                        const StoreFn& store, Progress& progress) = 0;
};

std::unique_ptr<Client> make_dicomweb_client(const PacsEndpoint& pacs);
std::unique_ptr<Client> make_dimse_client(const PacsEndpoint& pacs);

/// The SOPInstanceUID of a DICOM Part 10 file in memory; empty when the file does not parse to
/// its end (truncated or corrupt) or has no pixel data.
std::string sop_uid_of(const std::string& file_bytes);

}  // namespace organsmith::pacs_detail
