// The comparison chain of config/scenes/free-chain.toml as a LadderSpec, shared by the bench programs: pinned at its
// top-left corner, a straight column, block 1 kicked at 5 rad/s, no ladder logic.
#pragma once

#include "ladder/ladder.hpp"

namespace ladder::bench {

inline model::LadderSpec free_chain_spec(int n) {
  model::LadderSpec spec;
  spec.blocks = n;
  spec.length = 0.06, spec.thickness = 0.01, spec.mass = 0.02;
  spec.top = model::Top::Pinned;
  spec.start = model::Start::Straight;
  spec.logic = false;
  spec.kick_omega = 5.0;
  return spec;
}

}  // namespace ladder::bench
