// `organsmith pull` and pacs:// inputs against a real PACS: Debian's Orthanc with its DICOMweb and
// GDCM plugins, started on loopback with a temporary configuration (tests/support/orthanc_server.sh)
// and stopped by PID, also when a test fails.
#include "pacs/client.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <fstream>
#include <regex>
#include <sstream>
#include <thread>

using namespace organsmith::testing;
namespace fs = std::filesystem;

namespace {

constexpr const char* kUser = "radiology";
constexpr const char* kPassword = "s3cret-pw";

std::string script() { return std::string(ORGANSMITH_SOURCE_DIR) + "/tests/support/orthanc_server.sh"; }

class Orthanc {
 public:
  explicit Orthanc(const fs::path& dir) : dir_(dir) {
    const std::string cmd = "'" + script() + "' start '" + dir.string() + "' " + kUser + " " + kPassword + " > '" +
                            (dir.string() + ".ports") + "' 2> '" + (dir.string() + ".err") + "'";
    const int rc = std::system(cmd.c_str());
    missing_ = WIFEXITED(rc) && WEXITSTATUS(rc) == 3;
    std::istringstream in(read_file(dir.string() + ".ports"));
    up_ = WIFEXITED(rc) && WEXITSTATUS(rc) == 0 && (in >> http_port_ >> dicom_port_);
    error_ = read_file(dir.string() + ".err");
  }
  ~Orthanc() { stop(); }
  void stop() { (void)std::system(("'" + script() + "' stop '" + dir_.string() + "' > /dev/null 2>&1").c_str()); }
  bool up() const { return up_; }
  bool missing() const { return missing_; }
  const std::string& error() const { return error_; }
  std::string web() const { return "http://127.0.0.1:" + std::to_string(http_port_) + "/dicom-web"; }
  int http_port() const { return http_port_; }
  std::string dimse() const { return "dicom://ORTHANCTEST@127.0.0.1:" + std::to_string(dicom_port_); }
  /// Uploads every file of `folder` through the REST API; true when Orthanc took them all.
  bool upload(const fs::path& folder) const {
    for (const auto& e : fs::directory_iterator(folder)) {
      const std::string cmd = std::string("curl -s -f -o /dev/null -u ") + kUser + ":" + kPassword +
                              " -X POST --data-binary @'" + e.path().string() + "' http://127.0.0.1:" +
                              std::to_string(http_port_) + "/instances";
      if (std::system(cmd.c_str()) != 0) return false;
    }
    return true;
  }

 private:
  fs::path dir_;
  int http_port_ = 0, dicom_port_ = 0;
  bool up_ = false, missing_ = false;
  std::string error_;
};

std::string shell_output(const std::string& cmd) {
  std::string out;
  if (FILE* pipe = popen(cmd.c_str(), "r")) {
    char buf[4096];
    for (std::size_t n; (n = fread(buf, 1, sizeof buf, pipe)) > 0;) out.append(buf, n);
    pclose(pipe);
  }
  return out;
}

std::string dicom_tag(const fs::path& file, const std::string& tag) {
  const std::string out = shell_output("dcmdump -s -Un +P " + tag + " '" + file.string() + "'");
  std::smatch m;
  return std::regex_search(out, m, std::regex(R"(\[([0-9.]+)\])")) ? m[1].str() : "";
}

/// The pixel and geometry digest `organsmith run --until ingest` records for `input`.
std::string ingest_digest(const fs::path& input, const fs::path& scratch) {
  std::ofstream(scratch / "ingest.toml") << "[case]\ninput = \"" << input.string() << "\"\n";
  fs::remove_all(scratch / "ingest_out");
  const CliResult r = run_cli("-q run " + quoted(scratch / "ingest.toml") + " --out " + quoted(scratch / "ingest_out") +
                              " --until ingest");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  return read_json(scratch / "ingest_out" / "ingest.json").value("digest_sha256", "none");
}

nlohmann::json pull(const std::string& pacs, const std::string& study, const fs::path& cache, int* code = nullptr,
                    std::string* output = nullptr) {
  const CliResult r = run_cli("pull --json --retries 1 --pacs " + pacs + " --study " + study + " --cache " + quoted(cache));
  if (code) *code = r.exit_code;
  if (output) *output = r.output;
  const auto brace = r.output.find('{');
  if (r.exit_code != 0 || brace == std::string::npos) return nullptr;
  return nlohmann::json::parse(r.output.substr(brace, r.output.rfind('}') - brace + 1));
}

/// The study's cache folder as pull names it (the first 16 hex digits of the UID's SHA-256).
fs::path pull_dir_of(const fs::path& cache, const std::string& study) {
  const std::string digest = shell_output("printf '%s' '" + study + "' | sha256sum");
  return cache / digest.substr(0, 16);
}

/// A TCP port on loopback that nothing listens on now.
int free_port() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  close(fd);
  return ntohs(a.sin_port);
}

bool private_tree(const fs::path& dir) {
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    struct stat st {};
    if (stat(e.path().c_str(), &st) != 0) return false;
    const unsigned mode = st.st_mode & 0777;
    if (e.is_directory() ? mode != 0700 : mode != 0600) return false;
  }
  return true;
}

}  // namespace

TEST(Pacs, PullsByDicomWebAndDimseAsFromDiskAndRunsAPacsInput) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  ScratchDir tmp("pacs");
  Orthanc orthanc(tmp / "orthanc");
  if (orthanc.missing()) GTEST_SKIP() << "Orthanc is not installed (scripts/install-deps installs orthanc, orthanc-dicomweb, orthanc-gdcm)";
  ASSERT_TRUE(orthanc.up()) << orthanc.error();
  setenv("ORGANSMITH_PACS_USER", kUser, 1);
  setenv("ORGANSMITH_PACS_PASSWORD", kPassword, 1);

  const fs::path chest = real_data_dir() / "chest-dicom-8mm" / "dicom";
  // The abdomen series (JPEG 2000) has empty SOP Class, Study, Series and SOP Instance UIDs in its
  // data set, which a PACS refuses: a copy gets them from its file meta information and Frame of
  // Reference (pixels untouched).
  const fs::path abdomen = tmp / "abdomen";
  fs::create_directories(abdomen);
  for (const auto& e : fs::directory_iterator(real_data_dir() / "abdomen-dicom-2mm" / "dicom")) {
    const fs::path f = abdomen / e.path().filename();
    fs::copy_file(e.path(), f);
    fs::permissions(f, fs::perms::owner_write, fs::perm_options::add);
    const std::string cls = dicom_tag(f, "0002,0002"), sop = dicom_tag(f, "0002,0003"), frame = dicom_tag(f, "0020,0052");
    ASSERT_FALSE(cls.empty() || sop.empty() || frame.empty()) << f;
    ASSERT_EQ(std::system(("dcmodify -nb -m '(0008,0016)=" + cls + "' -m '(0008,0018)=" + sop + "' -m '(0020,000d)=" +
                           frame + ".1' -m '(0020,000e)=" + frame + ".2' '" + f.string() + "' > /dev/null 2>&1").c_str()),
              0);
  }
  ASSERT_TRUE(orthanc.upload(chest));
  ASSERT_TRUE(orthanc.upload(abdomen));
  const std::string chest_study = dicom_tag(fs::directory_iterator(chest)->path(), "0020,000d");
  const std::string abdomen_study = dicom_tag(fs::directory_iterator(abdomen)->path(), "0020,000d");

  for (const auto& [folder, study] : {std::pair{chest, chest_study}, std::pair{abdomen, abdomen_study}}) {
    const std::string on_disk = ingest_digest(folder, tmp.path());
    for (const std::string& pacs : {orthanc.web(), orthanc.dimse()}) {
      SCOPED_TRACE(pacs + " " + folder.filename().string());
      const fs::path cache = tmp / "cache" / (pacs.rfind("http", 0) == 0 ? "web" : "dimse");
      const auto first = pull(pacs, study, cache);
      ASSERT_TRUE(first.is_object());
      EXPECT_EQ(first["fetched"], first["instances"]);
      const fs::path study_dir = first["study_dir"].get<std::string>();
      EXPECT_EQ(ingest_digest(study_dir, tmp.path()), on_disk) << "pixels or geometry differ from the folder's";
      EXPECT_TRUE(private_tree(study_dir)) << "cache folders 0700, files 0600";
      EXPECT_EQ(pull(pacs, study, cache)["fetched"], 0) << "a re-pull fetches nothing";
      // A truncated instance is fetched again, and only it.
      fs::path victim;
      for (const auto& e : fs::recursive_directory_iterator(study_dir))
        if (e.is_regular_file()) victim = e.path();
      fs::resize_file(victim, fs::file_size(victim) / 2);
      const auto mended = pull(pacs, study, cache);
      EXPECT_EQ(mended["fetched"], 1);
      EXPECT_EQ(ingest_digest(study_dir, tmp.path()), on_disk);
    }
  }

  // DIMSE C-MOVE to our own C-STORE SCP (for a PACS without C-GET), once Orthanc knows our AE title.
  {
    const int port = free_port();
    const std::string http = orthanc.web().substr(0, orthanc.web().rfind('/'));
    ASSERT_EQ(std::system(("curl -s -f -o /dev/null -u " + std::string(kUser) + ":" + kPassword +
                           " -X PUT --data '{\"AET\":\"ORGANSMITH\",\"Host\":\"127.0.0.1\",\"Port\":" +
                           std::to_string(port) + "}' " + http + "/modalities/organsmith").c_str()), 0);
    const CliResult moved = run_cli("pull --json --pacs " + orthanc.dimse() + " --move-port " + std::to_string(port) +
                                    " --study " + chest_study + " --cache " + quoted(tmp / "cache" / "move"));
    ASSERT_EQ(moved.exit_code, 0) << moved.output;
    EXPECT_EQ(ingest_digest(pull_dir_of(tmp / "cache" / "move", chest_study), tmp.path()), ingest_digest(chest, tmp.path()));
  }

  // A case whose input is a PACS study gives the same outputs as the folder, and no patient name.
  std::ofstream(tmp / "pacs.toml") << "[case]\ninput = \"pacs://hospital/" << chest_study << "\"\n"
                                   << "[pacs.hospital]\nurl = \"" << orthanc.web() << "\"\ncache = \"case_cache\"\n"
                                   << "[[organ]]\nname = \"trachea\"\n";
  std::ofstream(tmp / "disk.toml") << "[case]\ninput = \"" << chest.string() << "\"\n[[organ]]\nname = \"trachea\"\n";
  const CliResult from_pacs = run_cli("-v run " + quoted(tmp / "pacs.toml") + " --out " + quoted(tmp / "out_pacs"));
  ASSERT_EQ(from_pacs.exit_code, 0) << from_pacs.output;
  const CliResult from_disk = run_cli("run " + quoted(tmp / "disk.toml") + " --out " + quoted(tmp / "out_disk"));
  ASSERT_EQ(from_disk.exit_code, 0) << from_disk.output;
  EXPECT_EQ(file_digests(tmp / "out_pacs", "manifest.json"), file_digests(tmp / "out_disk", "manifest.json"));
  EXPECT_FALSE(any_file_contains(tmp / "out_pacs", "Lung_Dx-A0002"));
  EXPECT_EQ(from_pacs.output.find("Lung_Dx-A0002"), std::string::npos);
  EXPECT_FALSE(any_file_contains(tmp / "out_pacs", chest_study)) << "the manifest keeps a hash of the study UID";
  EXPECT_EQ(from_pacs.output.find(kPassword), std::string::npos);

  // Each failure has its own exit code.
  int code = 0;
  std::string out;
  setenv("ORGANSMITH_PACS_PASSWORD", "wrong", 1);
  pull(orthanc.web(), chest_study, tmp / "c2", &code, &out);
  EXPECT_EQ(code, 91) << out;
  EXPECT_EQ(out.find("wrong"), std::string::npos) << "a password never reaches a log";
  setenv("ORGANSMITH_PACS_PASSWORD", kPassword, 1);
  pull(orthanc.web(), "1.2.3.4.5", tmp / "c2", &code, &out);
  EXPECT_EQ(code, 92) << out;
  pull(orthanc.dimse(), "1.2.3.4.5", tmp / "c2", &code, &out);
  EXPECT_EQ(code, 92) << out;
  pull("dicom://NOTTHEPACS@127.0.0.1:" + orthanc.dimse().substr(orthanc.dimse().rfind(':') + 1), chest_study, tmp / "c2",
       &code, &out);
  EXPECT_EQ(code, 91) << out;
  orthanc.stop();
  pull(orthanc.web(), chest_study, tmp / "c2", &code, &out);
  EXPECT_EQ(code, 90) << out;
  pull(orthanc.dimse(), chest_study, tmp / "c2", &code, &out);
  EXPECT_EQ(code, 90) << out;

  const fs::path chest_dir = pull_dir_of(tmp / "cache" / "web", chest_study);
  ASSERT_TRUE(fs::exists(chest_dir));
  const CliResult purge = run_cli("pull --purge --study " + chest_study + " --cache " + quoted(tmp / "cache" / "web"));
  EXPECT_EQ(purge.exit_code, 0) << purge.output;
  EXPECT_FALSE(fs::exists(chest_dir));
  EXPECT_FALSE(fs::exists(chest_dir.string() + ".index.json"));
  EXPECT_TRUE(fs::exists(pull_dir_of(tmp / "cache" / "web", abdomen_study))) << "other studies stay";
}

// What arrives from a PACS is kept only when it parses to its end: a transfer cut off inside an
// instance (uncompressed or JPEG 2000) is fetched again instead of cached.
TEST(Pacs, AnInstanceCutOffInTransitIsNotTakenForWhole) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  ScratchDir tmp("pacs-cut");
  // The JPEG 2000 slice needs its SOP Instance UID filled in (see above).
  const fs::path j2k = tmp / "j2k.dcm";
  fs::copy_file(fs::directory_iterator(real_data_dir() / "abdomen-dicom-2mm" / "dicom")->path(), j2k);
  fs::permissions(j2k, fs::perms::owner_write, fs::perm_options::add);
  ASSERT_EQ(std::system(("dcmodify -nb -m '(0008,0018)=" + dicom_tag(j2k, "0002,0003") + "' '" + j2k.string() +
                         "' > /dev/null 2>&1").c_str()), 0);
  for (const fs::path& file : {fs::directory_iterator(real_data_dir() / "chest-dicom-8mm" / "dicom")->path(), j2k}) {
    const std::string bytes = read_file(file);
    SCOPED_TRACE(file.string());
    EXPECT_FALSE(organsmith::pacs_detail::sop_uid_of(bytes).empty());
    for (std::size_t keep : {bytes.size() - 1, bytes.size() / 2, bytes.size() - 2000, std::size_t(1000), std::size_t(200)})
      EXPECT_TRUE(organsmith::pacs_detail::sop_uid_of(bytes.substr(0, keep)).empty()) << "cut at " << keep;
  }
}

// Credentials from a netrc file (NETRC) instead of the environment: the session and the query go
// through (the study asked for does not exist: exit 92, not a credential failure), and a wrong
// password there is exit 91; no password reaches the output.
TEST(Pacs, NetrcCredentialsWorkAndAWrongOneIsRefused) {
  ScratchDir tmp("pacs-netrc");
  Orthanc orthanc(tmp / "orthanc");
  if (orthanc.missing()) GTEST_SKIP() << orthanc.error();
  ASSERT_TRUE(orthanc.up()) << orthanc.error();
  unsetenv("ORGANSMITH_PACS_USER");
  unsetenv("ORGANSMITH_PACS_PASSWORD");
  for (const auto& [password, code] : {std::pair<std::string, int>{kPassword, 92}, {"not-the-password", 91}}) {
    std::ofstream(tmp / "netrc") << "machine 127.0.0.1 login " << kUser << " password " << password << "\n";
    fs::permissions(tmp / "netrc", fs::perms::owner_read | fs::perms::owner_write);
    setenv("NETRC", (tmp / "netrc").c_str(), 1);
    const CliResult r = run_cli("pull --retries 1 --pacs " + orthanc.web() + " --study 1.2.3.4.5 --cache " + quoted(tmp / "cache"));
    unsetenv("NETRC");
    EXPECT_EQ(r.exit_code, code) << password << "\n" << r.output;
    EXPECT_EQ(r.output.find(password), std::string::npos) << "a password never reaches a log";
  }
  orthanc.stop();
}

namespace {

/// tests/support/tls_proxy.py in front of `backend_port`, stopped by PID when the object dies.
class TlsProxy {
 public:
  TlsProxy(const fs::path& dir, const fs::path& cert, const fs::path& key, int backend_port) {
    const std::string cmd = "python3 '" + std::string(ORGANSMITH_SOURCE_DIR) + "/tests/support/tls_proxy.py' '" +
                            cert.string() + "' '" + key.string() + "' " + std::to_string(backend_port) + " > '" +
                            (dir / "proxy.port").string() + "' 2> '" + (dir / "proxy.err").string() + "' & echo $! > '" +
                            (dir / "proxy.pid").string() + "'";
    if (std::system(cmd.c_str()) != 0) return;
    std::istringstream(read_file(dir / "proxy.pid")) >> pid_;
    for (const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
         port_ == 0 && std::chrono::steady_clock::now() < until;) {
      std::istringstream(read_file(dir / "proxy.port")) >> port_;
      if (port_ == 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }
  ~TlsProxy() {
    if (pid_ > 0) kill(pid_, SIGTERM);
  }
  int port() const { return port_; }

 private:
  int pid_ = 0, port_ = 0;
};

}  // namespace

// Over HTTPS, through a TLS-terminating reverse proxy in front of Orthanc (how Orthanc's own
// documentation serves HTTPS; Debian 12's Orthanc 1.10.1 with its own SslEnabled segfaults on the
// first HTTPS connection, with RSA and EC certificates alike). The certificate is signed by a test
// CA: with --ca-file naming that CA the query goes through (the study asked for does not exist:
// exit 92); without it, exit 91 saying the certificate is not trusted.
TEST(Pacs, OverHttpsTheCaFileIsWhatTrustsTheServer) {
  ScratchDir tmp("pacs-tls");
  Orthanc orthanc(tmp / "orthanc");
  if (orthanc.missing()) GTEST_SKIP() << orthanc.error();
  ASSERT_TRUE(orthanc.up()) << orthanc.error();
  const std::string d = tmp.path().string();
  const std::string openssl =
      "cd '" + d + "' && openssl req -x509 -newkey rsa:2048 -nodes -keyout ca.key -out ca.pem -days 2 "
      "-subj '/CN=organsmith test CA' && openssl req -newkey rsa:2048 -nodes -keyout server.key -out server.csr "
      "-subj '/CN=127.0.0.1' && printf 'subjectAltName=IP:127.0.0.1\\n' > ext.cnf && openssl x509 -req -in server.csr "
      "-CA ca.pem -CAkey ca.key -CAcreateserial -out server.pem -days 2 -extfile ext.cnf";
  ASSERT_EQ(std::system(("(" + openssl + ") > '" + d + "/openssl.log' 2>&1").c_str()), 0) << read_file(tmp / "openssl.log");
  TlsProxy proxy(tmp.path(), tmp / "server.pem", tmp / "server.key", orthanc.http_port());
  ASSERT_GT(proxy.port(), 0) << read_file(tmp / "proxy.err");
  setenv("ORGANSMITH_PACS_USER", kUser, 1);
  setenv("ORGANSMITH_PACS_PASSWORD", kPassword, 1);
  const std::string web = "https://127.0.0.1:" + std::to_string(proxy.port()) + "/dicom-web";
  const std::string pull = "pull --retries 1 --pacs " + web + " --study 1.2.3.4.5 --cache " + quoted(tmp / "cache");
  const CliResult trusted = run_cli(pull + " --ca-file " + quoted(tmp / "ca.pem"));
  EXPECT_EQ(trusted.exit_code, 92) << trusted.output;
  const CliResult untrusted = run_cli(pull);
  EXPECT_EQ(untrusted.exit_code, 91) << untrusted.output;
  EXPECT_NE(untrusted.output.find("certificate"), std::string::npos) << untrusted.output;
  EXPECT_NE(untrusted.output.find("--ca-file"), std::string::npos) << untrusted.output;
  unsetenv("ORGANSMITH_PACS_USER");
  unsetenv("ORGANSMITH_PACS_PASSWORD");
}
