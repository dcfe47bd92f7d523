#include "transport/security.hpp"

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/pkcs7.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>

#include <ctime>
#include <filesystem>
#include <memory>
#include <optional>
#include <regex>

namespace ladder::transport {

namespace fs = std::filesystem;

const char* role_name(Role r) {
  switch (r) {
    case Role::Server: return "server";
    case Role::Controller: return "controller";
    case Role::Viewer: return "viewer";
  }
  return "?";
}

namespace {

template <class T, void (*F)(T*)>
struct Free {
  void operator()(T* p) const { F(p); }
};
using X509Ptr = std::unique_ptr<X509, Free<X509, X509_free>>;
using KeyPtr = std::unique_ptr<EVP_PKEY, Free<EVP_PKEY, EVP_PKEY_free>>;
using BioPtr = std::unique_ptr<BIO, Free<BIO, BIO_free_all>>;
using StorePtr = std::unique_ptr<X509_STORE, Free<X509_STORE, X509_STORE_free>>;
using StoreCtxPtr = std::unique_ptr<X509_STORE_CTX, Free<X509_STORE_CTX, X509_STORE_CTX_free>>;
using Pkcs7Ptr = std::unique_ptr<PKCS7, Free<PKCS7, PKCS7_free>>;

// OpenSSL's last error as text (and its queue emptied), for the end of a message.
std::string openssl_error() {
  std::string text;
  while (const unsigned long e = ERR_get_error()) {
    char buf[256];
    ERR_error_string_n(e, buf, sizeof buf);
    text = buf;  // the last one is the outermost
  }
  return text.empty() ? "no detail from OpenSSL" : text;
}

BioPtr open_file(const std::string& path) {
  BioPtr b(BIO_new_file(path.c_str(), "r"));
  if (!b) throw SecurityError(path + ": cannot read it: " + openssl_error());
  return b;
}

X509Ptr read_cert(const std::string& path) {
  X509Ptr c(PEM_read_bio_X509(open_file(path).get(), nullptr, nullptr, nullptr));
  if (!c) throw SecurityError(path + ": not a PEM certificate (" + openssl_error() + ")");
  return c;
}

std::string asn1_time_text(const ASN1_TIME* t) {
  std::tm tm{};
  if (ASN1_TIME_to_tm(t, &tm) != 1) return "(unreadable date)";
  char buf[64];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S UTC", &tm);
  return buf;
}

std::string name_text(const X509_NAME* n, unsigned long flags) {
  BioPtr b(BIO_new(BIO_s_mem()));
  X509_NAME_print_ex(b.get(), n, 0, flags);
  char* data = nullptr;
  const long len = BIO_get_mem_data(b.get(), &data);
  return std::string(data, static_cast<std::size_t>(len));
}

std::string common_name(const X509* c) {
  char buf[256] = {};
  X509_NAME_get_text_by_NID(X509_get_subject_name(c), NID_commonName, buf, sizeof buf);
  return buf;
}

// The validity of the certificate now: expired and not yet valid are the two ways a date makes it unusable.
void check_dates(const X509* c, const std::string& path, const std::string& what) {
  if (X509_cmp_current_time(X509_get0_notAfter(c)) < 0)
    throw SecurityError(path + ": " + what + " expired on " + asn1_time_text(X509_get0_notAfter(c)) +
                        " (make a new one with scripts/make-pki)");
  if (X509_cmp_current_time(X509_get0_notBefore(c)) > 0)
    throw SecurityError(path + ": " + what + " is not valid before " + asn1_time_text(X509_get0_notBefore(c)) +
                        " (is this machine's clock right?)");
}

StorePtr trust(const X509* ca) {
  StorePtr store(X509_STORE_new());
  X509_STORE_add_cert(store.get(), const_cast<X509*>(ca));
  return store;
}

void check_signed_by(X509* cert, X509_STORE* store, const std::string& cert_path, const std::string& ca_path) {
  StoreCtxPtr ctx(X509_STORE_CTX_new());
  X509_STORE_CTX_init(ctx.get(), store, cert, nullptr);
  if (X509_verify_cert(ctx.get()) == 1) return;
  const int err = X509_STORE_CTX_get_error(ctx.get());
  throw SecurityError(cert_path + ": not signed by " + ca_path + ", the CA of this deployment (" +
                      X509_verify_cert_error_string(err) + "); was it made with another CA's make-pki folder?");
}

// Verifies an S/MIME document signed by the CA (as the access-control plugin does: text mode) and returns its text.
std::string signed_text(const std::string& path, X509_STORE* store, const std::string& ca_path) {
  BioPtr in = open_file(path);
  BIO* content = nullptr;
  Pkcs7Ptr p7(SMIME_read_PKCS7(in.get(), &content));
  BioPtr content_owner(content);
  if (!p7) throw SecurityError(path + ": not an S/MIME signed document (" + openssl_error() + ")");
  BioPtr out(BIO_new(BIO_s_mem()));
  if (PKCS7_verify(p7.get(), nullptr, store, content, out.get(), PKCS7_TEXT) != 1)
    throw SecurityError(path + ": its signature does not verify with " + ca_path + " (" + openssl_error() +
                        "); was it signed by another CA, or changed since?");
  char* data = nullptr;
  const long len = BIO_get_mem_data(out.get(), &data);
  return std::string(data, static_cast<std::size_t>(len));
}

// "YYYY-MM-DDTHH:MM:SS" (the permissions' validity) as seconds since the epoch; nullopt if it is not one.
std::optional<std::time_t> xml_time(const std::string& text) {
  std::tm tm{};
  const char* end = strptime(text.c_str(), "%Y-%m-%dT%H:%M:%S", &tm);
  if (end == nullptr) return std::nullopt;
  return timegm(&tm);
}

// The role the permissions grant to `subject`, checking the grant's validity window.
Role granted_role(const std::string& xml, const std::string& subject, const std::string& path) {
  static const std::regex grant(R"re(<grant\s+name="([^"]*)">([\s\S]*?)</grant>)re");
  static const std::regex subj(R"(<subject_name>\s*([^<]*?)\s*</subject_name>)");
  static const std::regex from(R"(<not_before>\s*([^<]*?)\s*</not_before>)");
  static const std::regex to(R"(<not_after>\s*([^<]*?)\s*</not_after>)");
  for (std::sregex_iterator it(xml.begin(), xml.end(), grant), end; it != end; ++it) {
    const std::string name = (*it)[1], body = (*it)[2];
    std::smatch m;
    if (!std::regex_search(body, m, subj) || m[1] != subject) continue;
    const std::time_t now = std::time(nullptr);
    std::smatch a, b;
    if (std::regex_search(body, a, from) && std::regex_search(body, b, to)) {
      const auto t0 = xml_time(a[1]), t1 = xml_time(b[1]);
      if (t1 && *t1 < now) throw SecurityError(path + ": the grant '" + name + "' expired on " + b[1].str() + " UTC");
      if (t0 && *t0 > now) throw SecurityError(path + ": the grant '" + name + "' is not valid before " + a[1].str() +
                                               " UTC (is this machine's clock right?)");
    }
    if (name == "ladder_server") return Role::Server;
    if (name == "ladder_controller") return Role::Controller;
    if (name == "ladder_viewer") return Role::Viewer;
    throw SecurityError(path + ": the grant '" + name +
                        "' is none of ladder_server, ladder_controller, ladder_viewer (scripts/make-pki's)");
  }
  throw SecurityError(path + ": grants nothing to '" + subject + "', the subject of the identity's cert.pem; are "
                      "they from two different make-pki runs?");
}

const Identity* g_default = nullptr;

}  // namespace

Identity load_identity(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw SecurityError(dir + (fs::exists(dir, ec) ? ": a file, not an identity folder" : ": no such folder") +
                        " (scripts/make-pki DIR --server, --controller or --viewer NAME makes DIR/NAME)");
  Identity id;
  id.dir = dir;
  const fs::path base = fs::absolute(dir, ec);
  std::string* files[] = {&id.ca, &id.cert, &id.key, &id.governance, &id.permissions};
  const char* names[] = {"ca.pem", "cert.pem", "key.pem", "governance.p7s", "permissions.p7s"};
  for (int k = 0; k < 5; ++k) {
    *files[k] = (base / names[k]).string();
    if (!fs::is_regular_file(*files[k], ec))
      throw SecurityError((fs::path(dir) / names[k]).string() + ": missing (an identity folder of scripts/make-pki "
                          "has ca.pem, cert.pem, key.pem, governance.p7s and permissions.p7s)");
  }
  ERR_clear_error();
  const X509Ptr ca = read_cert(id.ca);
  const X509Ptr cert = read_cert(id.cert);
  check_dates(ca.get(), id.ca, "the CA certificate");
  id.name = common_name(cert.get());
  id.subject = name_text(X509_get_subject_name(cert.get()), XN_FLAG_RFC2253);
  id.not_after = asn1_time_text(X509_get0_notAfter(cert.get()));
  check_dates(cert.get(), id.cert, "the identity '" + id.name + "'");
  const StorePtr store = trust(ca.get());
  check_signed_by(cert.get(), store.get(), id.cert, id.ca);
  const KeyPtr key(PEM_read_bio_PrivateKey(open_file(id.key).get(), nullptr, nullptr, nullptr));
  if (!key) throw SecurityError(id.key + ": not a PEM private key without a password (" + openssl_error() + ")");
  if (X509_check_private_key(cert.get(), key.get()) != 1)
    throw SecurityError(id.key + ": not the private key of " + id.cert);
  signed_text(id.governance, store.get(), id.ca);
  id.role = granted_role(signed_text(id.permissions, store.get(), id.ca), id.subject, id.permissions);
  return id;
}

void require_role(const Identity& id, std::initializer_list<Role> allowed, const std::string& program) {
  std::string want;
  for (const Role r : allowed) {
    if (r == id.role) return;
    want += std::string(want.empty() ? "" : " or ") + role_name(r);
  }
  throw SecurityError(program + " needs a " + want + " identity, but " + id.dir + " is the " + role_name(id.role) +
                      " '" + id.name + "'");
}

void apply_security(Qos& qos, const Identity& id) {
  dds_qos_t* q = qos.get();
  // Short library names: Debian's libddsc finds them in its own folder (/usr/lib/<arch>/libddsc0debian).
  dds_qset_prop(q, "dds.sec.auth.library.path", "dds_security_auth");
  dds_qset_prop(q, "dds.sec.auth.library.init", "init_authentication");
  dds_qset_prop(q, "dds.sec.auth.library.finalize", "finalize_authentication");
  dds_qset_prop(q, "dds.sec.access.library.path", "dds_security_ac");
  dds_qset_prop(q, "dds.sec.access.library.init", "init_access_control");
  dds_qset_prop(q, "dds.sec.access.library.finalize", "finalize_access_control");
  dds_qset_prop(q, "dds.sec.crypto.library.path", "dds_security_crypto");
  dds_qset_prop(q, "dds.sec.crypto.library.init", "init_crypto");
  dds_qset_prop(q, "dds.sec.crypto.library.finalize", "finalize_crypto");
  // One CA signs both the identities and the documents (scripts/make-pki).
  dds_qset_prop(q, "dds.sec.auth.identity_ca", ("file:" + id.ca).c_str());
  dds_qset_prop(q, "dds.sec.auth.identity_certificate", ("file:" + id.cert).c_str());
  dds_qset_prop(q, "dds.sec.auth.private_key", ("file:" + id.key).c_str());
  dds_qset_prop(q, "dds.sec.access.permissions_ca", ("file:" + id.ca).c_str());
  dds_qset_prop(q, "dds.sec.access.governance", ("file:" + id.governance).c_str());
  dds_qset_prop(q, "dds.sec.access.permissions", ("file:" + id.permissions).c_str());
}

void set_default_identity(const Identity* id) { g_default = id; }
const Identity* default_identity() { return g_default; }

}  // namespace ladder::transport
