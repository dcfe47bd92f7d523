// Decoders of our own for the session log's LCM types (msgs/lcm/*.lcm). A log is untrusted input: lcm-gen's
// decoders resize vectors to counts read from the file, and lcm_coretypes.h computes array sizes in int (a count of
// 2^28 + 1 doubles overflows it and the decoder reads past the buffer). These check every count and length against
// the bytes that remain and against a stated maximum before anything is allocated, check the type's fingerprint,
// require the payload to be consumed exactly, and then check the values each record must have on its own (finite,
// within range). Writing stays with lcm-gen's encoders: the files are LCM's format, for lcm-logplayer and lcm-spy.
//
// No DDS here (and no file): a fuzzer links this alone.
#pragma once

#include "ladder/limits.hpp"
#include "ladderlcm/checkpoint_t.hpp"
#include "ladderlcm/command_t.hpp"
#include "ladderlcm/event_t.hpp"
#include "ladderlcm/scene_t.hpp"
#include "ladderlcm/state_t.hpp"

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace ladder::transport {

// The most a log may hold. docs/recording.md states them.
inline constexpr std::int32_t kLogMaxBlocks = kMaxBlocks;   // what a scene file may ask for (ladder.blocks)
inline constexpr std::int32_t kLogMaxOverrides = kMaxOverrides;  // --set overrides of one scene
// A scene file's text, and each --set override of it (ladder.masses may be long): 1e6 masses take about 8 MB.
inline constexpr std::size_t kLogMaxSceneText = kMaxSceneFile;
inline constexpr std::size_t kLogMaxText = 64u << 10;       // every other string (names, reasons, details)
inline constexpr double kLogMaxSimTime = 1e7;               // [s] of simulated time in one scene (116 days)
// Steps in one scene: kLogMaxSimTime at the smallest time step a scene may have (sim.dt >= 1e-7 s).
inline constexpr std::int64_t kLogMaxStep = 100'000'000'000'000;
inline constexpr double kLogMinDt = kMinDt, kLogMaxDt = kMaxDt;  // [s] sim.dt's range in scene files
inline constexpr std::int64_t kLogMaxCommands = 1'000'000'000'000'000;  // command_seq, commands_applied

// Decodes one event's data as the type: "" when it decodes, every byte used and every value sane; else what is
// wrong, naming the field ("num_blocks = 268435457 is more than 1000000 (...)"). `out` is then unspecified.
std::string decode_lcm(std::span<const std::uint8_t> data, ladderlcm::scene_t& out);
std::string decode_lcm(std::span<const std::uint8_t> data, ladderlcm::state_t& out);
std::string decode_lcm(std::span<const std::uint8_t> data, ladderlcm::command_t& out);
std::string decode_lcm(std::span<const std::uint8_t> data, ladderlcm::event_t& out);
std::string decode_lcm(std::span<const std::uint8_t> data, ladderlcm::checkpoint_t& out);

// The checks on values alone that decode_lcm applies after decoding ("" or what is wrong): generation, step,
// command_seq and counts not negative (and within kLogMaxCommands), steps within kLogMaxStep, times finite and within
// kLogMaxSimTime, a scene's dt within sim.dt's range, every coordinate, mass and accepted command's parameter finite.
std::string check_record(const ladderlcm::scene_t& m);
std::string check_record(const ladderlcm::state_t& m);
std::string check_record(const ladderlcm::command_t& m);
std::string check_record(const ladderlcm::event_t& m);
std::string check_record(const ladderlcm::checkpoint_t& m);

}  // namespace ladder::transport
