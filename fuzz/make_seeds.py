#!/usr/bin/env python3
"""Seed corpus of fuzz_event_log, cut from a short real log:

    build/apps/manip_sim --out x.lcm --movements 9 --reps 1
    python3 fuzz/make_seeds.py x.lcm fuzz/corpus/event_log

Seeds (about 130 kB together): the head of the log; one complete perturbed
trial shrunk to 81 states around its onset (START, states, ONSET, truth twin
states, truth impedance, END, with the cycle fields of START/END set to the
cut); the same trial in a third-party writer's order (START after the first
state, END before the last); and that trial damaged (a flipped length bit,
garbage with a fake event magic, a truncated last event)."""
import os
import struct
import sys

src, out = sys.argv[1], sys.argv[2]
b = open(src, "rb").read()
events = []  # (offset, channel, total bytes, data offset)
at = 0
while at + 28 <= len(b):
    magic, _n, _t, cl, dl = struct.unpack(">IqqII", b[at:at + 28])
    assert magic == 0xEDA1DA01
    events.append((at, b[at + 28:at + 28 + cl].decode(), 28 + cl + dl, at + 28 + cl))
    at += 28 + cl + dl


def raw(i):
    o, _c, t, _d = events[i]
    return bytearray(b[o:o + t])


def state_cycle(i):  # state_t payload: fingerprint, cycle
    return struct.unpack(">q", b[events[i][3] + 8:events[i][3] + 16])[0]


def with_event_cycle(ev, cycle):  # trial_event_t payload: fingerprint, utime, cycle
    d = ev.index(b"MANIP_TRIAL") + len("MANIP_TRIAL")
    ev[d + 16:d + 24] = struct.pack(">q", cycle)
    return ev


os.makedirs(out, exist_ok=True)
open(os.path.join(out, "head"), "wb").write(b[:events[150][0]])

onset = next(i for i, e in enumerate(events) if e[1] == "MANIP_TRIAL" and raw(i)[-60:] and
             raw(i)[events[i][3] - events[i][0] + 8 + 8 + 8 + 4] == 2)
start = max(i for i in range(onset) if events[i][1] == "MANIP_TRIAL")
end = next(i for i in range(onset + 1, len(events)) if events[i][1] == "MANIP_TRIAL")
states = [i for i in range(onset - 60, onset + 60) if events[i][1] == "MANIP_STATE"][20:101]
c0, c1 = state_cycle(states[0]), state_cycle(states[-1])
twins = [i for i in range(onset, end) if events[i][1] == "MANIP_TRUTH_STATE" and c0 <= state_cycle(i) <= c1]
truth = [i for i in range(onset, end) if events[i][1] == "MANIP_TRUTH_IMPEDANCE"]
sess, st, en = raw(0), with_event_cycle(raw(start), c0), with_event_cycle(raw(end), c1)
body = [raw(i) for i in states]
k = states.index(onset + 1) if onset + 1 in states else len(body) // 2
body.insert(k, raw(onset))
tail = [raw(i) for i in twins] + [raw(i) for i in truth]
trial = sess + st + b"".join(body) + b"".join(tail) + en
open(os.path.join(out, "trial"), "wb").write(trial)
# Third-party order: START after the first state, END before the last.
reordered = sess + body[0] + st + b"".join(body[1:-1]) + en + body[-1] + b"".join(tail)
open(os.path.join(out, "trial_reordered"), "wb").write(reordered)
# Damaged: flip a data-length bit of the 10th state, insert garbage with a
# fake magic after the 30th, cut the last event short.
dmg = bytearray(sess + st)
for j, e in enumerate(body):
    e = bytearray(e)
    if j == 10:
        e[24] ^= 0x10
    dmg += e
    if j == 30:
        dmg += b"\x5a" * 40 + struct.pack(">IqqII", 0xEDA1DA01, 0, 0, 11, 5000) + b"MANIP_STATE" + b"\x5a" * 60
dmg += b"".join(tail) + en[:-20]
open(os.path.join(out, "trial_damaged"), "wb").write(dmg)
for f in sorted(os.listdir(out)):
    print(f, os.path.getsize(os.path.join(out, f)))
