"""Display configuration: a YAML file read strictly.

Every key is known, typed and range-checked; duplicate keys, unknown keys and
wrong types are refused with ``file:line: key: reason`` (the same form as the
C++ strict reader, include/manip/common/yaml_reader.hpp). Missing keys take
the defaults below, which describe a 24" 1920x1080 monitor at 1:1 scale.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Tuple

import yaml


class ConfigError(Exception):
    """A bad configuration: the message is the one line to print."""


@dataclass
class Screen:
    width_px: int = 1920          # pixels of the full screen
    height_px: int = 1080
    width_m: float = 0.531        # visible image size (measure it: docs/display.md)
    height_m: float = 0.299
    refresh_hz: float = 60.0      # frame rate the display paces itself to


@dataclass
class Mapping:
    # shoulder-frame point drawn at the centre of the window
    center_shoulder_m: Tuple[float, float] = (0.0, 0.425)
    scale: float = 1.0            # screen metres per shoulder-frame metre (1 = veridical)
    rotation_deg: float = 0.0     # counter-clockwise rotation of the shoulder axes on the screen
    mirror_x: bool = False        # flip left-right (after rotation), e.g. a mirror above the hand
    mirror_y: bool = False        # flip up-down


@dataclass
class Appearance:
    cursor_radius_m: float = 0.005       # handle dot (shoulder-frame metres, scaled like targets)
    background: Tuple[int, int, int] = (0, 0, 0)
    cursor: Tuple[int, int, int] = (0, 255, 0)          # the paper's green dot
    start_target: Tuple[int, int, int] = (128, 128, 128)
    goal_rest: Tuple[int, int, int] = (110, 0, 0)       # between trials (rest / return to start)
    goal_go: Tuple[int, int, int] = (255, 200, 0)       # go: reach now
    goal_hold: Tuple[int, int, int] = (0, 120, 255)     # hold in the goal
    goal_done: Tuple[int, int, int] = (70, 70, 70)      # session done
    text: Tuple[int, int, int] = (200, 200, 200)
    show_phase_text: bool = True         # phase name in the top-left corner
    show_trigger_line: bool = False      # perturbation trigger line (operator view / calibration)
    stale_after_s: float = 0.5           # hide the cursor when no state arrived for this long


@dataclass
class Frame:
    """Workspace -> shoulder transform used until a MANIP_SESSION arrives
    (a display started after the session began never sees it)."""
    workspace_origin_in_shoulder_m: Tuple[float, float] = (0.0, 0.425)
    workspace_to_shoulder_rot_rad: float = 0.0


@dataclass
class DisplayConfig:
    screen: Screen = field(default_factory=Screen)
    mapping: Mapping = field(default_factory=Mapping)
    appearance: Appearance = field(default_factory=Appearance)
    fallback_frame: Frame = field(default_factory=Frame)
    source: str = "(defaults)"


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate keys and records line numbers."""


def _construct_mapping(loader, node, deep=False):
    seen: Dict[Any, int] = {}
    for k, _v in node.value:
        key = loader.construct_object(k, deep=deep)
        if key in seen:
            raise ConfigError("%s:%d: %s: duplicate key (first at line %d)"
                              % (loader.name, k.start_mark.line + 1, key, seen[key]))
        seen[key] = k.start_mark.line + 1
    m = _Lined(loader.construct_pairs(node, deep=True))
    m.lines = seen
    return m


class _Lined(dict):
    lines: Dict[str, int] = {}


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _color(v) -> bool:
    return (isinstance(v, list) and len(v) == 3 and all(isinstance(c, int) and not isinstance(c, bool)
                                                       and 0 <= c <= 255 for c in v))


def _finite_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _pair(v) -> bool:
    return isinstance(v, list) and len(v) == 2 and all(_finite_num(c) for c in v)


# section -> key -> (check, what it must be, converter)
_POS = (lambda v: _finite_num(v) and v > 0, "a finite number > 0", float)
_NUM = (_finite_num, "a finite number", float)
_POS_INT = (lambda v: isinstance(v, int) and not isinstance(v, bool) and 0 < v <= 16384,
            "an integer in 1..16384", int)
_BOOL = (lambda v: isinstance(v, bool), "true or false", bool)
_COLOR = (_color, "[r, g, b] with integers 0..255", tuple)
_PAIR = (_pair, "[x1, x2] of finite numbers", lambda v: (float(v[0]), float(v[1])))
_SCHEMA = {
    "screen": (Screen, {"width_px": _POS_INT, "height_px": _POS_INT, "width_m": _POS, "height_m": _POS,
                        "refresh_hz": (lambda v: _finite_num(v) and 1 <= v <= 1000, "a number in 1..1000 [Hz]",
                                       float)}),
    "mapping": (Mapping, {"center_shoulder_m": _PAIR, "scale": _POS, "rotation_deg": _NUM,
                          "mirror_x": _BOOL, "mirror_y": _BOOL}),
    "appearance": (Appearance, {"cursor_radius_m": _POS, "background": _COLOR, "cursor": _COLOR,
                                "start_target": _COLOR, "goal_rest": _COLOR, "goal_go": _COLOR,
                                "goal_hold": _COLOR, "goal_done": _COLOR, "text": _COLOR,
                                "show_phase_text": _BOOL, "show_trigger_line": _BOOL, "stale_after_s": _POS}),
    "fallback_frame": (Frame, {"workspace_origin_in_shoulder_m": _PAIR, "workspace_to_shoulder_rot_rad": _NUM}),
}


def parse(text: str, name: str) -> DisplayConfig:
    """Parse configuration text; ``name`` is used in messages (a path)."""
    try:
        loader = _StrictLoader(text)
        loader.name = name
        try:
            doc = loader.get_single_data()
        finally:
            loader.dispose()
    except ConfigError:
        raise
    except yaml.MarkedYAMLError as e:
        line = e.problem_mark.line + 1 if e.problem_mark else 0
        raise ConfigError("%s:%d: not valid YAML: %s" % (name, line, e.problem))
    except yaml.YAMLError as e:
        raise ConfigError("%s: not valid YAML: %s" % (name, e))
    cfg = DisplayConfig(source=name)
    if doc is None:
        return cfg
    if not isinstance(doc, dict):
        raise ConfigError("%s:1: top level must be a mapping of sections (%s)" % (name, ", ".join(_SCHEMA)))
    for section, body in doc.items():
        line = getattr(doc, "lines", {}).get(section, 0)
        if section not in _SCHEMA:
            raise ConfigError("%s:%d: %s: unknown section (known: %s)" % (name, line, section, ", ".join(_SCHEMA)))
        cls, keys = _SCHEMA[section]
        if not isinstance(body, dict):
            raise ConfigError("%s:%d: %s: must be a mapping of keys" % (name, line, section))
        obj = getattr(cfg, section)
        for key, value in body.items():
            kline = getattr(body, "lines", {}).get(key, line)
            if key not in keys:
                raise ConfigError("%s:%d: %s.%s: unknown key (known: %s)"
                                  % (name, kline, section, key, ", ".join(keys)))
            check, what, conv = keys[key]
            if not check(value):
                raise ConfigError("%s:%d: %s.%s: must be %s, got %r" % (name, kline, section, key, what, value))
            setattr(obj, key, conv(value))
    return cfg


def load(path: str) -> DisplayConfig:
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as e:
        raise ConfigError("%s: cannot read: %s" % (path, e.strerror or e))
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError("%s: byte offset %d: not UTF-8 text" % (path, e.start))
    return parse(text, path)
