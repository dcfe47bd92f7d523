#!/usr/bin/env python3
"""Writes the seed corpus of session_log_fuzz (corpus/session_log_fuzz/) from a real session log, cut small:
`ladderd --record session.lcmlog`, a few ladderctl commands (tip, poke, set, grab, drag, release, pause, step,
resume, reset), Ctrl-C; then `cut_log_seeds.py session.lcmlog`. Each seed keeps the first events of each channel."""
import collections
import os
import struct
import sys

data = open(sys.argv[1], 'rb').read()
events, at = [], 0
while at + 28 <= len(data):
    sync, _number, _utime, channel_len, data_len = struct.unpack('>IqqII', data[at:at + 28])
    assert sync == 0xEDA1DA01, f'no sync word at byte {at}'
    end = at + 28 + channel_len + data_len
    events.append((data[at + 28:at + 28 + channel_len].decode(), data[at:end]))
    at = end


def first(limits):
    taken, out = collections.Counter(), []
    for channel, raw in events:
        if taken[channel] < limits.get(channel, 0):
            taken[channel] += 1
            out.append(raw)
    return b''.join(out)


out_dir = sys.argv[2] if len(sys.argv) > 2 else os.path.join(os.path.dirname(__file__), 'corpus', 'session_log_fuzz')
os.makedirs(out_dir, exist_ok=True)
small = first({'LADDER_SCENE': 2, 'LADDER_STATE': 3, 'LADDER_COMMAND': 9, 'LADDER_CHECKPOINT': 2})
seeds = {
    'scene-only.lcmlog': first({'LADDER_SCENE': 1}),
    'session-small.lcmlog': small,
    'session-cut-off.lcmlog': small[:-50],
    'states-commands.lcmlog': first({'LADDER_SCENE': 1, 'LADDER_STATE': 1, 'LADDER_COMMAND': 3,
                                     'LADDER_CHECKPOINT': 1}),
}
for name, content in seeds.items():
    with open(os.path.join(out_dir, name), 'wb') as file:
        file.write(content)
