// DIMSE through DCMTK's DcmSCU: C-FIND (study root) to find the study, its CT series and their
// instances; C-GET to retrieve them on the same association (the C-STORE sub-operations arrive
// on it, so the storage classes are proposed with the SCP role). Only uncompressed transfer
// syntaxes are proposed: the PACS converts compressed images (DCMTK here has no JPEG 2000 codec).
#include "pacs/client.h"

#include "core/errors.h"

#include <dcmtk/config/osconfig.h>
#include <dcmtk/dcmdata/dctk.h>
#include <dcmtk/dcmdata/dcistrmb.h>
#include <dcmtk/dcmdata/dcostrmb.h>
#include <dcmtk/dcmnet/diutil.h>
#include <dcmtk/dcmnet/dstorscp.h>
#include <dcmtk/dcmnet/scu.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <mutex>
#include <thread>
#include <unistd.h>

namespace organsmith::pacs_detail {

namespace {

/// DCMTK's own log stays silent: every failure is reported by organsmith, in words, once.
void quiet_dcmtk() {
  static std::once_flag once;
  std::call_once(once, [] { OFLog::configure(OFLogger::FATAL_LOG_LEVEL); });
}

std::string hex4(unsigned v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "%04x", v & 0xffffu);
  return buf;
}

/// The keys of a C-GET or C-MOVE: the whole series when `sop` is empty, else that instance.
void retrieve_keys(DcmDataset& q, const std::string& study, const std::string& series, const std::string& sop) {
  q.putAndInsertOFStringArray(DCM_QueryRetrieveLevel, sop.empty() ? "SERIES" : "IMAGE");
  q.putAndInsertOFStringArray(DCM_StudyInstanceUID, study.c_str());
  q.putAndInsertOFStringArray(DCM_SeriesInstanceUID, series.c_str());
  if (!sop.empty()) q.putAndInsertOFStringArray(DCM_SOPInstanceUID, sop.c_str());
}

/// One request for the whole series when `sops` is empty, else one per instance.
template <typename F>
void for_each_request(const std::vector<std::string>& sops, F&& request) {
  if (sops.empty()) return request(std::string());
  for (const auto& sop : sops) request(sop);
}

/// The last response's status (0xffff when none came) and failed sub-operations; frees the list.
Uint16 final_status(OFList<RetrieveResponse*>& responses, unsigned* failed) {
  Uint16 status = 0xffff;
  if (!responses.empty()) {
    status = responses.back()->m_status;
    if (failed) *failed = responses.back()->m_numberOfFailedSubops;
  }
  for (auto* r : responses) delete r;
  responses.clear();
  return status;
}

/// The SCU with its C-STORE sub-operations handed to a callback, as Part 10 bytes in memory.
class Scu final : public DcmSCU {
 public:
  const StoreFn* store = nullptr;
  std::string store_error;

 protected:
  OFCondition handleSTORERequest(const T_ASC_PresentationContextID, DcmDataset* incoming, OFBool& go_on,
                                 Uint16& status) override {
    go_on = OFTrue;
    status = STATUS_Success;
    if (!incoming) return EC_Normal;
    // DcmSCU hands the received data set over: this handler owns it and must free it (each one
    // holds a whole instance's pixels). The file object takes it without a copy.
    DcmFileFormat file(incoming, OFFalse);
    if (!store) return EC_Normal;
    const E_TransferSyntax xfer = incoming->getOriginalXfer();
    file.transferInit();
    const Uint32 length = file.calcElementLength(xfer, EET_ExplicitLength) + 1024;
    std::string bytes(length, '\0');
    DcmOutputBufferStream out(bytes.data(), length);
    file.transferInit();
    const OFCondition c = file.write(out, xfer, EET_ExplicitLength, nullptr);
    file.transferEnd();
    if (c.bad()) {
      store_error = c.text();
      status = STATUS_STORE_Refused_OutOfResources;
      return EC_Normal;
    }
    void* buffer = nullptr;
    offile_off_t written = 0;
    out.flushBuffer(buffer, written);
    bytes.resize(std::size_t(written));
    (*store)(std::move(bytes));
    return EC_Normal;
  }
};

/// Our C-STORE SCP for C-MOVE: listens on a port in its own thread and keeps what it receives as
/// files in a private folder until the move is over.
class MoveReceiver final : public DcmStorageSCP {
 public:
  MoveReceiver(const std::string& aet, int port, const std::filesystem::path& dir) {
    setAETitle(aet.c_str());
    setPort(Uint16(port));
    setOutputDirectory(dir.c_str());
    setConnectionBlockingMode(DUL_NOBLOCK);
    setConnectionTimeout(1);  // listen() looks at stop_ once a second
    OFList<OFString> ts;
    ts.push_back(UID_LittleEndianExplicitTransferSyntax);
    ts.push_back(UID_LittleEndianImplicitTransferSyntax);
    for (const char* sop_class : {UID_CTImageStorage, UID_EnhancedCTImageStorage}) addPresentationContext(sop_class, ts);
  }
  void start() {
    thread_ = std::thread([this] { result_ = listen(); });
  }
  void stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  ~MoveReceiver() override { stop(); }
  const OFCondition& result() const { return result_; }

 protected:
  OFBool stopAfterConnectionTimeout() override { return stop_.load(); }
  OFBool stopAfterCurrentAssociation() override { return stop_.load(); }

 private:
  std::atomic<bool> stop_{false};
  std::thread thread_;
  OFCondition result_ = EC_Normal;
};

class DimseClient final : public Client {
 public:
  explicit DimseClient(const PacsEndpoint& p) : pacs_(p) {
    quiet_dcmtk();
    setenv("TCP_NODELAY", "1", 0);  // DCMTK reads it at connect: without it every C-STORE waits ~40 ms
  }

  bool has_study(const std::string& study) override {
    DcmDataset q;
    q.putAndInsertOFStringArray(DCM_QueryRetrieveLevel, "STUDY");
    q.putAndInsertOFStringArray(DCM_StudyInstanceUID, study.c_str());
    return !find(q, DCM_StudyInstanceUID).empty();
  }

  std::vector<std::string> ct_series(const std::string& study) override {
    DcmDataset q;
    q.putAndInsertOFStringArray(DCM_QueryRetrieveLevel, "SERIES");
    q.putAndInsertOFStringArray(DCM_StudyInstanceUID, study.c_str());
    q.putAndInsertOFStringArray(DCM_SeriesInstanceUID, "");
    q.putAndInsertOFStringArray(DCM_Modality, "CT");
    return find(q, DCM_SeriesInstanceUID);
  }

  std::vector<std::string> instances(const std::string& study, const std::string& series) override {
    DcmDataset q;
    q.putAndInsertOFStringArray(DCM_QueryRetrieveLevel, "IMAGE");
    q.putAndInsertOFStringArray(DCM_StudyInstanceUID, study.c_str());
    q.putAndInsertOFStringArray(DCM_SeriesInstanceUID, series.c_str());
    q.putAndInsertOFStringArray(DCM_SOPInstanceUID, "");
    return find(q, DCM_SOPInstanceUID);
  }

  void retrieve(const std::string& study, const std::string& series, const std::vector<std::string>& sops,
                const StoreFn& store, Progress& progress) override {
    auto one = [&](const std::string& sop) {
      progress.check_cancelled();
      Scu scu;
      connect(scu, true);
      scu.store = &store;
      DcmDataset q;
      retrieve_keys(q, study, series, sop);
      OFList<RetrieveResponse*> responses;
      const T_ASC_PresentationContextID pc =
          scu.findPresentationContextID(UID_GETStudyRootQueryRetrieveInformationModel, "");
      const OFCondition c = scu.sendCGETRequest(pc, &q, &responses);
      unsigned failed = 0;
      const Uint16 status = final_status(responses, &failed);
      scu.releaseAssociation();
      if (c.bad())
        throw PacsError(ExitCode::pacs_transfer, std::string("C-GET broke off: ") + c.text());
      if (!scu.store_error.empty())
        throw PacsError(ExitCode::pacs_transfer, "an instance received by C-GET could not be kept: " + scu.store_error);
      if (status != STATUS_Success && status != 0xff00)
        throw PacsError(ExitCode::pacs_transfer, "C-GET ended with status 0x" + hex4(status) + (failed ? " (" + std::to_string(failed) + " failed)" : ""),
                        "the PACS' log says why (e.g. it cannot convert the images to an uncompressed transfer syntax)");
    };
    if (pacs_.move_port > 0) return move(study, series, sops, store, progress);
    for_each_request(sops, one);
  }

  /// C-MOVE to our own C-STORE SCP: the PACS opens an association to us and stores the instances.
  void move(const std::string& study, const std::string& series, const std::vector<std::string>& sops,
            const StoreFn& store, Progress& progress) {
    char tmpl[] = "/tmp/organsmith-move-XXXXXX";  // private (0700) until the files are handed on
    if (!mkdtemp(tmpl)) throw PacsError(ExitCode::internal, "cannot create a folder for C-MOVE");
    const std::filesystem::path dir = tmpl;
    struct Cleanup {
      std::filesystem::path d;
      ~Cleanup() {
        std::error_code ec;
        std::filesystem::remove_all(d, ec);
      }
    } cleanup{dir};
    MoveReceiver receiver(pacs_.calling_aet, pacs_.move_port, dir);
    receiver.start();
    auto one = [&](const std::string& sop) {
      progress.check_cancelled();
      Scu scu;
      connect(scu, false, UID_MOVEStudyRootQueryRetrieveInformationModel);
      DcmDataset q;
      retrieve_keys(q, study, series, sop);
      OFList<RetrieveResponse*> responses;
      const T_ASC_PresentationContextID pc =
          scu.findPresentationContextID(UID_MOVEStudyRootQueryRetrieveInformationModel, "");
      const OFCondition c = scu.sendMOVERequest(pc, pacs_.calling_aet.c_str(), &q, &responses);
      const Uint16 status = final_status(responses, nullptr);
      scu.releaseAssociation();
      if (c.bad()) throw PacsError(ExitCode::pacs_transfer, std::string("C-MOVE broke off: ") + c.text());
      if (status == 0xA801)
        throw PacsError(ExitCode::pacs_refused, "the PACS does not know our AE title '" + pacs_.calling_aet + "' as a C-MOVE destination",
                        "register it at the PACS with this host and port " + std::to_string(pacs_.move_port));
      if (status != STATUS_Success && status != 0xff00)
        throw PacsError(ExitCode::pacs_transfer, "C-MOVE ended with status 0x" + hex4(status),
                        "the PACS' log says why (it must reach us at port " + std::to_string(pacs_.move_port) + ")");
    };
    for_each_request(sops, one);
    receiver.stop();
    for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) {
      if (!e.is_regular_file()) continue;
      std::ifstream in(e.path(), std::ios::binary);
      store(std::string(std::istreambuf_iterator<char>(in), {}));
    }
  }

 private:
  void connect(Scu& scu, bool retrieve, const char* query_model = UID_FINDStudyRootQueryRetrieveInformationModel) {
    scu.setAETitle(pacs_.calling_aet.c_str());
    scu.setPeerHostName(pacs_.host.c_str());
    scu.setPeerPort(Uint16(pacs_.port));
    scu.setPeerAETitle(pacs_.called_aet.c_str());
    scu.setConnectionTimeout(Sint32(std::min(pacs_.timeout_s, 30.0)));
    scu.setACSETimeout(Uint32(pacs_.timeout_s));
    scu.setDIMSETimeout(Uint32(pacs_.timeout_s));
    scu.setDIMSEBlockingMode(DIMSE_NONBLOCKING);
    scu.setMaxReceivePDULength(131072);
    OFList<OFString> ts;
    ts.push_back(UID_LittleEndianExplicitTransferSyntax);
    ts.push_back(UID_LittleEndianImplicitTransferSyntax);
    scu.addPresentationContext(retrieve ? UID_GETStudyRootQueryRetrieveInformationModel : query_model, ts);
    if (retrieve)
      for (const char* sop_class : {UID_CTImageStorage, UID_EnhancedCTImageStorage})
        scu.addPresentationContext(sop_class, ts, ASC_SC_ROLE_SCP);
    OFCondition c = scu.initNetwork();
    if (c.bad()) throw PacsError(ExitCode::internal, std::string("cannot start DICOM networking: ") + c.text());
    c = scu.negotiateAssociation();
    const std::string peer = pacs_.called_aet + "@" + pacs_.host + ":" + std::to_string(pacs_.port);
    if (c == DUL_ASSOCIATIONREJECTED)
      throw PacsError(ExitCode::pacs_refused,
                      "the PACS " + peer + " rejected the association (AE titles not accepted)",
                      "check the PACS' AE title in the URL (dicom://AET@host:port) and that it knows our AE title "
                      "'" + pacs_.calling_aet + "' (--calling-aet)");
    if (c == DUL_PEERABORTEDASSOCIATION)
      throw PacsError(ExitCode::pacs_refused, "the PACS " + peer + " aborted the association",
                      "the PACS may not allow our AE title '" + pacs_.calling_aet + "' to query or retrieve");
    if (c.bad())
      throw PacsError(ExitCode::pacs_unreachable, "the PACS " + peer + " does not answer (" + std::string(c.text()) + ")",
                      "check host, port and that the server runs and is reachable from here");
  }

  std::vector<std::string> find(DcmDataset& q, const DcmTagKey& key) {
    Scu scu;
    connect(scu, false);
    const T_ASC_PresentationContextID pc = scu.findPresentationContextID(UID_FINDStudyRootQueryRetrieveInformationModel, "");
    OFList<QRResponse*> responses;
    const OFCondition c = scu.sendFINDRequest(pc, &q, &responses);
    std::vector<std::string> out;
    Uint16 status = 0;
    for (QRResponse* r : responses) {
      OFString v;
      if (r->m_dataset && r->m_dataset->findAndGetOFString(key, v).good() && !v.empty()) out.push_back(v.c_str());
      status = r->m_status;
      delete r;
    }
    scu.releaseAssociation();
    if (c.bad()) throw PacsError(ExitCode::pacs_transfer, std::string("C-FIND broke off: ") + c.text());
    if (status != STATUS_Success)
      throw PacsError(ExitCode::pacs_refused, "C-FIND ended with status 0x" + hex4(status),
                      "the PACS may not allow our AE title '" + pacs_.calling_aet + "' to query");
    return out;
  }

  PacsEndpoint pacs_;
};

}  // namespace

std::unique_ptr<Client> make_dimse_client(const PacsEndpoint& pacs) { return std::make_unique<DimseClient>(pacs); }

std::string sop_uid_of(const std::string& bytes) {
  quiet_dcmtk();
  if (bytes.size() < 132 || bytes.compare(128, 4, "DICM") != 0) return {};
  DcmInputBufferStream in;
  in.setBuffer(bytes.data(), offile_off_t(bytes.size()));
  in.setEos();
  DcmFileFormat file;
  file.transferInit();
  const OFCondition c = file.read(in, EXS_Unknown, EGL_noChange, DCM_MaxReadLength);
  file.transferEnd();
  if (c.bad()) return {};
  DcmDataset* d = file.getDataset();
  OFString uid;
  DcmElement* pixels = nullptr;
  if (!d || d->findAndGetOFString(DCM_SOPInstanceUID, uid).bad() || uid.empty()) return {};
  // Encapsulated (compressed) pixel data has no length of its own: its presence is what counts; a
  // cut-off file already failed to parse above.
  if (d->findAndGetElement(DCM_PixelData, pixels).bad() || !pixels) return {};
  return uid.c_str();
}

}  // namespace organsmith::pacs_detail
