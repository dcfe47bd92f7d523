// DDS Security for ladder's participants (docs/security.md): the identity folder that scripts/make-pki writes,
// checked with OpenSSL before Cyclone sees it, and the participant QoS that turns on Cyclone's security plugins
// (authentication, access control, encryption) for it.
//
// Cyclone's own errors for bad security files are a bare "Not Allowed By Security" or a line in its trace; the checks
// here say which file is wrong and how (missing, expired and since when, signed by another CA, granting another role)
// so that a program can refuse to start with that message.
#pragma once

#include "transport/dds.hpp"

#include <initializer_list>
#include <stdexcept>
#include <string>

namespace ladder::transport {

// What a participant may do, from the grant of its signed permissions (scripts/make-pki names it "ladder_ROLE").
enum class Role {
  Server,      // publishes State, SceneInfo, Event, Stats, CommandAck; reads Command
  Controller,  // publishes Command; reads everything else
  Viewer,      // reads State, SceneInfo, Event, Stats; nothing else
};
const char* role_name(Role r);

class SecurityError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One participant's identity folder, DIR/NAME of scripts/make-pki, once checked.
struct Identity {
  std::string dir;       // as given
  std::string name;      // the certificate's common name
  std::string subject;   // the certificate's subject, RFC 2253 (as the permissions name it)
  Role role = Role::Viewer;
  std::string not_after;  // "YYYY-MM-DD HH:MM:SS UTC": the certificate's end of validity
  // Absolute paths of the five files.
  std::string ca, cert, key, governance, permissions;
};

// Reads and checks the folder: the five files are there; the certificate is valid now, signed by ca.pem and
// matches key.pem; both documents are signed by ca.pem; the permissions grant the certificate's subject one of the
// three roles and are valid now. Throws SecurityError naming the file and what is wrong with it.
Identity load_identity(const std::string& dir);

// Throws SecurityError unless the identity's role is one of `allowed`, e.g. "ladderd needs a server identity, but
// pki/v1 is the viewer 'v1'".
void require_role(const Identity& id, std::initializer_list<Role> allowed, const std::string& program);

// Sets the DDS Security properties of a participant QoS: Debian's Cyclone plugins and the identity's files.
void apply_security(Qos& q, const Identity& id);

// The identity make_participant uses when it is given none: set once by a program's main (--security), so that code
// which makes its participant deep inside (the server) needs no new argument. nullptr: no security (the default).
void set_default_identity(const Identity* id);
const Identity* default_identity();

}  // namespace ladder::transport
