// The ladder's six DDS topics (msgs/ladder.idl, DESIGN.md section 5), created on one participant.
#pragma once

#include "ladder.h"
#include "transport/dds.hpp"

namespace ladder::transport {

struct Topics {
  explicit Topics(const Entity& participant)
      : scene_info(make_topic(participant, &ladder_msg_SceneInfo_desc, "ladder/SceneInfo")),
        state(make_topic(participant, &ladder_msg_State_desc, "ladder/State")),
        command(make_topic(participant, &ladder_msg_Command_desc, "ladder/Command")),
        ack(make_topic(participant, &ladder_msg_CommandAck_desc, "ladder/CommandAck")),
        event(make_topic(participant, &ladder_msg_Event_desc, "ladder/Event")),
        stats(make_topic(participant, &ladder_msg_Stats_desc, "ladder/Stats")) {}

  Entity scene_info, state, command, ack, event, stats;
};

}  // namespace ladder::transport
