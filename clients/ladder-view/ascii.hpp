// --ascii: the ladder as text, drawn by the same module as the window and the PNG, then read back cell by cell.
#pragma once

#include "draw.hpp"

#include <string>

namespace ladder::view {

// The picture as `rows` lines of `cols` characters: '#' the blocks' wide faces, ':' their narrow sides, '.' their
// ends, '+' ribbons, '%' the hand, 'o' hinges, '@' locked hinges, 'x' broken ones, '*' grips, and each block's
// number at its centre when it fits on the block. The camera is for an image of cols x 2*rows pixels (a character
// cell is twice as tall as it is wide).
std::string render_ascii(const Camera& cam, const client::SceneInfo& info, const client::State& state, int cols,
                         int rows);

}  // namespace ladder::view
