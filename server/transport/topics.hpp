// The ladder's six DDS topics (msgs/ladder.idl, docs/server.md), created on one participant.
#pragma once

#include "ladder.h"
#include "transport/dds.hpp"

#include <cstdint>
#include <vector>

namespace ladder::transport {

struct Topics {
  // commands = false: without Command and CommandAck (left empty), for a participant whose DDS Security
  // permissions grant neither (a viewer's): Cyclone refuses to create a topic the permissions do not name.
  explicit Topics(const Entity& participant, bool commands = true)
      : scene_info(make_topic(participant, &ladder_msg_SceneInfo_desc, "ladder/SceneInfo")),
        state(make_topic(participant, &ladder_msg_State_desc, "ladder/State")),
        command(commands ? make_topic(participant, &ladder_msg_Command_desc, "ladder/Command") : Entity()),
        ack(commands ? make_topic(participant, &ladder_msg_CommandAck_desc, "ladder/CommandAck") : Entity()),
        event(make_topic(participant, &ladder_msg_Event_desc, "ladder/Event")),
        stats(make_topic(participant, &ladder_msg_Stats_desc, "ladder/Stats")) {}

  Entity scene_info, state, command, ack, event, stats;
};

// Lends a State its blocks and hinges in the message's flat layout (msgs/ladder.idl), for one write: x, y, theta per
// block in `poses`, and per hinge its corner, status and flip-flops. The vectors must outlive the write.
inline void lend_blocks(ladder_msg_State& m, const std::vector<double>& poses, const std::vector<std::uint8_t>& corner,
                        const std::vector<ladder_msg_HingeStatus>& status, const std::vector<std::uint32_t>& flips) {
  lend(m.poses, poses);
  lend(m.hinge_corner, corner);
  lend(m.hinge_status, status);
  lend(m.hinge_flips, flips);
}

}  // namespace ladder::transport
