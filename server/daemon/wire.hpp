// A DDS Command as the session reads it: its fields, once (daemon/command.hpp makes the typed command of them).
#pragma once

#include "daemon/command.hpp"
#include "ladder.h"  // generated from msgs/ladder.idl

namespace ladder::daemon {

// The kind is read as a number: an enum object holding a value beyond the enum's range (a caller that filled the
// struct from elsewhere) is undefined behaviour at its first read.
CommandFields fields_of(const ladder_msg_Command& c);

}  // namespace ladder::daemon
