#!/usr/bin/env python3
"""Writes the seed corpus of command_fuzz (corpus/command_fuzz/): real command sequences, as ladderctl sends them,
in the byte layout command_fuzz.cpp reads (one record per command; see command() there)."""
import os
import struct
import sys

KINDS = ['tip', 'poke', 'push', 'grab', 'drag', 'release', 'break', 'join', 'pause', 'resume', 'step', 'reset',
         'set', 'load']
SPECIAL = {0.0: 0, 0.5: 10, -1.0: 11, 1.0: 12, 10.0: 15}  # indices into command_fuzz.cpp's kSpecial


def number(v):
    if v in SPECIAL and not (v == 0.0 and str(v).startswith('-')):
        return struct.pack('<B', SPECIAL[v])
    return struct.pack('<Bd', 200, v)  # tag >= 128: the double as it is


def command(kind, block=0, hinge=0, count=0, point=None, target=None, angle=None, a=0.0, b=0.0, e=0.0, f=0.0,
            text='', steps=2):
    c, d = point or (0.0, 0.0)
    f = angle if angle is not None else f  # f without has_angle: a value the command should ignore
    if target:
        a, b = target
    flags = (point is not None) | (target is not None) << 1 | (angle is not None) << 2
    out = struct.pack('<BBbbBQ', KINDS.index(kind), flags, block, hinge, count, 1)
    out += b''.join(number(x) for x in (a, b, c, d, e, f))
    out += struct.pack('<B', 6) + b'ladder' + struct.pack('<B', 4) + b'seed'
    out += struct.pack('<H', len(text)) + text.encode()
    return out + struct.pack('<B', steps)


SEEDS = {
    'tip': [command('tip', steps=4)],
    'poke': [command('poke', block=3, a=0.01, b=0.0), command('poke', block=0, point=(0.0, -0.03), a=0.0, b=0.02)],
    'push': [command('push', block=2, a=0.5, b=0.0, e=0.5)],
    'grab-drag-release': [command('grab', block=2), command('drag', block=2, target=(0.05, -0.1), angle=0.5),
                          command('release', block=2)],
    'break-join': [command('break', hinge=3), command('join', hinge=3)],
    'pause-step-resume': [command('pause'), command('step', count=3, steps=4), command('resume')],
    'set-live': [command('set', text='damping.linear=0.5'), command('set', text='sim.gravity=[0,-9.81]'),
                 command('set', text='server.publish_rate=30'), command('reset')],
    'load': [command('load', text='double-ripple'), command('tip')],
    # Found by command_fuzz on 06c87de: accepted, and State publishes grips[0].angle = nan (issue 18).
    'found-grab-unheld-nan-angle': [command('grab', block=2, f=float('nan'))],
}

out_dir = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), 'corpus', 'command_fuzz')
os.makedirs(out_dir, exist_ok=True)
for name, commands in SEEDS.items():
    with open(os.path.join(out_dir, name), 'wb') as file:
        file.write(b''.join(commands))
