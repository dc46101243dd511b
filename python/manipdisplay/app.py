"""manipdisplay main program: the pygame loop and the LCM subscriptions."""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import select
import signal
import sys
import tempfile
import time
from typing import Optional

from manipdisplay import config as cfgmod
from manipdisplay import exit_codes as ec
from manipdisplay.geometry import ScreenMap, workspace_to_shoulder
from manipdisplay.stats import FrameStats

VERSION = "0.1.0"

# state_t.PHASE_* -> what the participant sees (rest, go, hold, done); NONE shows no cue.
PHASE_NAMES = {0: "none", 1: "rest", 2: "go", 3: "go", 4: "hold", 5: "done", 6: "rest"}

EPILOG = """exit codes (docs/exit-codes.md):
  0    ended by Esc, q, closing the window or --duration
  2    usage: bad command line
  3    config: the display YAML is invalid or unreadable (file:line: key: reason)
  6    output: --stats-json or a snapshot cannot be written (exists without --force)
  8    the screen cannot be opened (no X display / SDL video driver)
  10   bus: the LCM bus cannot be created with the given URL
  70   internal error (a bug: please report it)
  130  stopped by SIGINT/SIGTERM/SIGHUP (statistics summarised, outputs closed)
"""


class UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit code 2 (argparse's default is also 2, but prints usage)
        raise UsageError(message)


def _size(text: str):
    m = re.fullmatch(r"(\d{1,5})x(\d{1,5})", text)
    if not m or not (0 < int(m.group(1)) <= 16384 and 0 < int(m.group(2)) <= 16384):
        raise argparse.ArgumentTypeError("expected WxH in pixels, e.g. 1024x768, got %r" % text)
    return int(m.group(1)), int(m.group(2))


def _pos_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError("not a number: %r" % text)
    if not math.isfinite(v) or v < 0:
        raise argparse.ArgumentTypeError("must be a finite number >= 0, got %r" % text)
    return v


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="manipdisplay", description="Participant display for manip_rt: start and goal targets, "
                "the handle as a green dot and the trial phase, in the shoulder frame (docs/display.md).",
                epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", help="display YAML (screen geometry, mapping, colours); default: built-in defaults")
    p.add_argument("--windowed", type=_size, metavar="WxH", help="a window of WxH pixels instead of full screen")
    p.add_argument("--lcm-url", default=None, help="LCM URL (default: $LCM_DEFAULT_URL or LCM's default)")
    p.add_argument("--id", default="display", help="name in MANIP_DISPLAY_HEALTH (several screens)")
    p.add_argument("--calibration", action="store_true",
                   help="draw a 5 cm grid and a 10 cm scale bar to check the geometry with a ruler")
    p.add_argument("--duration", type=_pos_float, default=0.0, help="quit after this many seconds (0 = run until Esc)")
    p.add_argument("--stats-json", metavar="PATH", help="write the frame-timing summary as JSON on exit")
    p.add_argument("--snapshot-dir", metavar="DIR",
                   help="on SIGUSR1 (or key s) save the presented frame as snap-NNN.png plus snap-NNN.json "
                        "(what it shows: cycle, trial, phase, targets)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --stats-json file")
    p.add_argument("-q", "--quiet", action="store_true", help="no summary on exit")
    p.add_argument("--version", action="version", version="manipdisplay " + VERSION)
    return p


def _import_types():
    env = os.environ.get("MANIP_LCMTYPES_PYTHON")
    here = os.path.dirname(os.path.abspath(__file__))
    for d in ([env] if env else []) + [os.path.normpath(os.path.join(here, "..", "..", "build", "python"))]:
        if d and os.path.isdir(os.path.join(d, "manip")) and d not in sys.path:
            sys.path.insert(0, d)
    from manip import session_t, state_t, trial_event_t, targets_t, display_health_t  # noqa: F401
    return session_t, state_t, trial_event_t, targets_t, display_health_t


def write_json_atomically(path: str, obj, force: bool) -> None:
    """Write to a temporary file next to ``path`` and rename: a crash never
    leaves a truncated file, and an existing file survives unless ``force``."""
    d = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".manipdisplay-", dir=d)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(obj, f, indent=1, sort_keys=True, allow_nan=True)
            f.write("\n")
        if force:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)  # fails with EEXIST instead of replacing
            os.unlink(tmp)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


class Display:
    def __init__(self, args, cfg, types, lc):
        self.args, self.cfg, self.lc = args, cfg, lc
        (self.session_t, self.state_t, self.trial_event_t, self.targets_t, self.health_t) = types
        self.stats = FrameStats(cfg.screen.refresh_hz)
        self.state = None               # newest state_t
        self.state_rx = None            # monotonic time it arrived
        self.state_shown_cycle = None   # cycle of the state in the last presented frame
        self.frame_origin = cfg.fallback_frame.workspace_origin_in_shoulder_m
        self.frame_rot = cfg.fallback_frame.workspace_to_shoulder_rot_rad
        self.have_session = False
        self.targets = None             # newest targets_t
        self.trial_event = None
        self.snapshot_requested = False
        self.snap_index = 0
        self.stop_code: Optional[int] = None
        lc.subscribe("MANIP_STATE_LIVE", self.on_state).set_queue_capacity(1000)
        lc.subscribe("MANIP_SESSION", self.on_session)
        lc.subscribe("MANIP_TRIAL", self.on_trial)
        lc.subscribe("MANIP_TARGETS", self.on_targets)

    # --- LCM handlers (never raise: a bad message is counted, not fatal)
    def _decode(self, cls, data):
        try:
            return cls.decode(data)
        except Exception:  # noqa: BLE001 - any malformed message from the bus
            self.stats.decode_errors += 1
            return None

    def on_state(self, _ch, data):
        m = self._decode(self.state_t, data)
        if m is None:
            return
        self.stats.states_received += 1
        self.state, self.state_rx = m, time.monotonic()

    def on_session(self, _ch, data):
        m = self._decode(self.session_t, data)
        if m is None or not all(map(math.isfinite, list(m.workspace_origin_in_shoulder_m) +
                                    [m.workspace_to_shoulder_rot_rad])):
            return
        self.frame_origin = tuple(m.workspace_origin_in_shoulder_m)
        self.frame_rot = m.workspace_to_shoulder_rot_rad
        self.have_session = True

    def on_trial(self, _ch, data):
        m = self._decode(self.trial_event_t, data)
        if m is not None:
            self.trial_event = m

    def on_targets(self, _ch, data):
        m = self._decode(self.targets_t, data)
        if m is not None and all(map(math.isfinite, list(m.start_shoulder_m) + list(m.goal_shoulder_m) +
                                     [m.target_radius_m, m.trigger_x2_shoulder_m])):
            self.targets = m

    # --- what to draw
    def current_targets(self):
        """(start, goal, radius, trigger, seq) from MANIP_TARGETS, else from the last trial event."""
        if self.targets is not None:
            t = self.targets
            return (tuple(t.start_shoulder_m), tuple(t.goal_shoulder_m), t.target_radius_m,
                    t.trigger_x2_shoulder_m, t.command_seq)
        if self.trial_event is not None:
            e = self.trial_event
            return tuple(e.start_shoulder_m), tuple(e.goal_shoulder_m), 0.01, float("nan"), -1
        return None

    def draw(self, pg, surf, smap, font):
        a = self.cfg.appearance
        surf.fill(a.background)
        if self.args.calibration:
            self.draw_calibration(pg, surf, smap, font)
            return {}
        now = time.monotonic()
        fresh = self.state is not None and now - self.state_rx <= a.stale_after_s
        phase = self.state.phase if fresh else (self.targets.phase if self.targets is not None else 0)
        name = PHASE_NAMES.get(phase, "none")
        shown = {"phase": int(phase), "phase_name": name}
        tg = self.current_targets()
        if tg is not None and name != "none":
            start, goal, radius, trigger, seq = tg
            r_px = max(1, int(round(smap.length_px(radius))))
            if a.show_trigger_line and math.isfinite(trigger):
                x0 = smap.to_px((smap.cx - 1.0, trigger))
                x1 = smap.to_px((smap.cx + 1.0, trigger))
                pg.draw.line(surf, a.text, x0, x1, 1)
            goal_colour = {"rest": a.goal_rest, "go": a.goal_go, "hold": a.goal_hold, "done": a.goal_done}[name]
            pg.draw.circle(surf, a.start_target, _round(smap.to_px(start)), r_px)
            pg.draw.circle(surf, goal_colour, _round(smap.to_px(goal)), r_px)
            shown.update(start_shoulder_m=list(start), goal_shoulder_m=list(goal), target_radius_m=radius,
                         targets_command_seq=int(seq))
        if fresh:
            s = self.state
            p_sh = workspace_to_shoulder(tuple(s.x_workspace_m), self.frame_origin, self.frame_rot)
            if all(map(math.isfinite, p_sh)):
                pg.draw.circle(surf, a.cursor, _round(smap.to_px(p_sh)),
                               max(1, int(round(smap.length_px(a.cursor_radius_m)))))
            shown.update(cycle=int(s.cycle), trial=int(s.trial), cursor_shoulder_m=list(p_sh),
                         state_utime=int(s.utime))
        if a.show_phase_text:
            label = name if fresh else ("waiting for manip_rt" if self.state is None else "no data")
            if fresh and not self.have_session:
                label += " (no session message: default frame)"
            surf.blit(font.render(label, True, a.text), (8, 8))
        return shown

    def draw_calibration(self, pg, surf, smap, font):
        a = self.cfg.appearance
        step = 0.05
        c = smap.cx, smap.cy
        for i in range(-10, 11):
            pg.draw.line(surf, (60, 60, 60), smap.to_px((c[0] + i * step, c[1] - 0.5)),
                         smap.to_px((c[0] + i * step, c[1] + 0.5)), 1)
            pg.draw.line(surf, (60, 60, 60), smap.to_px((c[0] - 0.5, c[1] + i * step)),
                         smap.to_px((c[0] + 0.5, c[1] + i * step)), 1)
        # 10 cm bars along both shoulder axes from the centre: measure them on the glass
        pg.draw.line(surf, a.cursor, smap.to_px(c), smap.to_px((c[0] + 0.10, c[1])), 3)
        pg.draw.line(surf, a.goal_go, smap.to_px(c), smap.to_px((c[0], c[1] + 0.10)), 3)
        surf.blit(font.render("calibration: grid 5 cm, green bar 10 cm along x1, yellow 10 cm along x2 "
                              "(shoulder frame, scale %.3g)" % smap.scale, True, a.text), (8, 8))

    def save_snapshot(self, pg, surf, shown):
        d = self.args.snapshot_dir
        while True:
            base = os.path.join(d, "snap-%03d" % self.snap_index)
            self.snap_index += 1
            if not os.path.exists(base + ".png") and not os.path.exists(base + ".json"):
                break
        # the JSON is written last: its presence means the PNG is complete
        tmp = base + ".tmp.png"
        pg.image.save(surf, tmp)
        os.replace(tmp, base + ".png")
        meta = dict(shown, window_px=list(surf.get_size()), wall_time_us=int(time.time() * 1e6),
                    frame_origin_shoulder_m=list(self.frame_origin), frame_rot_rad=self.frame_rot,
                    have_session=self.have_session)
        write_json_atomically(base + ".json", meta, force=False)

    def publish_health(self):
        s = self.stats.summary()
        m = self.health_t()
        m.utime = int(time.time() * 1e6)
        m.display_id = self.args.id
        for k, v in s.items():
            setattr(m, k, v)
        try:
            self.lc.publish("MANIP_DISPLAY_HEALTH", m.encode())
        except Exception:  # noqa: BLE001 - a full socket buffer must not stop the participant's screen
            pass

    def pump(self, deadline: float) -> None:
        """Handle bus messages as they arrive until ``deadline`` (monotonic):
        the reception time of a state is then accurate to the scheduler."""
        fd = self.lc.fileno()
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                r, _, _ = select.select([fd], [], [], 0)
                if not r:
                    return
            else:
                r, _, _ = select.select([fd], [], [], remaining)
            if r:
                self.lc.handle()


def _round(p):
    return int(round(p[0])), int(round(p[1]))


def main(argv=None) -> int:
    try:
        return _main(argv)
    except KeyboardInterrupt:
        return ec.INTERRUPTED
    except Exception as e:  # noqa: BLE001 - one line and the documented code, never a traceback
        print("manipdisplay: internal error (please report): %s: %s" % (type(e).__name__, e), file=sys.stderr)
        return ec.INTERNAL


def _main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except UsageError as e:
        print("manipdisplay: usage: %s (see --help)" % e, file=sys.stderr)
        return ec.USAGE
    try:
        cfg = cfgmod.load(args.config) if args.config else cfgmod.DisplayConfig()
    except cfgmod.ConfigError as e:
        print("manipdisplay: config: %s" % e, file=sys.stderr)
        return ec.CONFIG
    if args.stats_json and os.path.exists(args.stats_json) and not args.force:
        print("manipdisplay: output: --stats-json %s exists (use --force to overwrite)" % args.stats_json,
              file=sys.stderr)
        return ec.OUTPUT
    if args.snapshot_dir and not os.path.isdir(args.snapshot_dir):
        print("manipdisplay: output: --snapshot-dir %s is not a directory" % args.snapshot_dir, file=sys.stderr)
        return ec.OUTPUT
    try:
        types = _import_types()
    except ImportError as e:
        print("manipdisplay: internal: LCM types not found (build manip_lcmtypes_gen or set "
              "MANIP_LCMTYPES_PYTHON): %s" % e, file=sys.stderr)
        return ec.INTERNAL
    import lcm
    try:
        lc = lcm.LCM(args.lcm_url) if args.lcm_url else lcm.LCM()
    except Exception as e:  # noqa: BLE001 - lcm raises RuntimeError/IOError by version
        print("manipdisplay: bus: cannot create LCM with URL '%s': %s (for udpm: is there a multicast route?)"
              % (args.lcm_url or os.environ.get("LCM_DEFAULT_URL", "default"), e), file=sys.stderr)
        return ec.BUS
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import pygame as pg
    except ImportError as e:
        print("manipdisplay: the screen cannot be opened: pygame is missing (Debian: python3-pygame, "
              "scripts/setup.sh): %s" % e, file=sys.stderr)
        return ec.BACKEND
    try:
        pg.display.init()
        pg.font.init()
        if args.windowed:
            surf = pg.display.set_mode(args.windowed)
        else:
            # The desktop's own mode: changing the monitor's mode would change its pixel pitch.
            surf = pg.display.set_mode((0, 0), pg.FULLSCREEN)
            pg.mouse.set_visible(False)
            if surf.get_size() != (cfg.screen.width_px, cfg.screen.height_px):
                print("manipdisplay: warning: the screen is %dx%d px but %s says screen.width_px/height_px "
                      "%dx%d: the scaling is wrong until the configuration is fixed (docs/display.md)"
                      % (surf.get_size() + (cfg.source, cfg.screen.width_px, cfg.screen.height_px)), file=sys.stderr)
        pg.display.set_caption("manipdisplay")
    except pg.error as e:
        print("manipdisplay: the screen cannot be opened (DISPLAY=%s): %s"
              % (os.environ.get("DISPLAY", ""), e), file=sys.stderr)
        return ec.BACKEND
    smap = ScreenMap(cfg.screen, cfg.mapping, surf.get_size())
    font = pg.font.Font(None, 28)
    disp = Display(args, cfg, types, lc)

    def on_signal(signum, _frame):
        disp.stop_code = ec.INTERRUPTED

    def on_usr1(_signum, _frame):
        disp.snapshot_requested = True

    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, on_signal)
    if args.snapshot_dir:
        signal.signal(signal.SIGUSR1, on_usr1)

    period = 1.0 / cfg.screen.refresh_hz
    t0 = time.monotonic()
    next_frame = t0
    next_health = t0 + 1.0
    code = ec.OK
    try:
        while disp.stop_code is None:
            disp.pump(next_frame)
            for ev in pg.event.get():
                if ev.type == pg.QUIT or (ev.type == pg.KEYDOWN and ev.key in (pg.K_ESCAPE, pg.K_q)):
                    disp.stop_code = ec.OK
                elif ev.type == pg.KEYDOWN and ev.key == pg.K_s and args.snapshot_dir:
                    disp.snapshot_requested = True
            shown = disp.draw(pg, surf, smap, font)
            pg.display.flip()
            t_present = time.monotonic()
            disp.stats.presented(t_present)
            if disp.state is not None and disp.state.cycle != disp.state_shown_cycle and "cycle" in shown:
                disp.state_shown_cycle = disp.state.cycle
                disp.stats.shown(t_present - disp.state_rx, time.time() - disp.state.utime * 1e-6)
            if disp.snapshot_requested:
                disp.snapshot_requested = False
                try:
                    disp.save_snapshot(pg, surf, dict(shown, present_monotonic_s=t_present))
                except (OSError, pg.error) as e:
                    # the participant's screen keeps running: a snapshot is a diagnostic
                    print("manipdisplay: warning: snapshot in %s not written: %s" % (args.snapshot_dir, e),
                          file=sys.stderr)
            if t_present >= next_health:
                disp.publish_health()
                next_health += 1.0
            if args.duration and t_present - t0 >= args.duration:
                disp.stop_code = ec.OK
            # Pace on a fixed grid: a late frame does not shift later frames.
            next_frame += period
            if next_frame < t_present - period:
                next_frame = t_present
        code = disp.stop_code
    finally:
        pg.display.quit()
    disp.publish_health()
    summary = disp.stats.summary()
    if not args.quiet:
        print("manipdisplay: %d frames at %.4g Hz, %d dropped; frame interval p50 %.2f ms p99 %.2f ms; "
              "stream-to-display latency p50 %.2f ms p99 %.2f ms (%d of %d states shown)"
              % (summary["frames"], summary["refresh_hz"], summary["dropped_frames"],
                 summary["frame_interval_p50_ms"], summary["frame_interval_p99_ms"], summary["latency_p50_ms"],
                 summary["latency_p99_ms"], summary["states_shown"], summary["states_received"]))
    if args.stats_json:
        try:
            write_json_atomically(args.stats_json, dict(summary, display_id=args.id), force=args.force)
        except OSError as e:
            print("manipdisplay: output: --stats-json %s: %s" % (args.stats_json, e.strerror or e), file=sys.stderr)
            return ec.OUTPUT if code == ec.OK else code
    return code
