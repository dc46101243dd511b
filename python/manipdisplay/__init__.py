"""manipdisplay: the participant's visual feedback for manip (issue 13).

Subscribes to the live bus of ``manip_rt`` (MANIP_STATE_LIVE, MANIP_TRIAL,
MANIP_TARGETS, MANIP_SESSION) and draws, in the shoulder frame, the start and
goal targets, the handle as a green dot and the trial phase; publishes its own
frame-timing statistics on MANIP_DISPLAY_HEALTH. See docs/display.md.
"""
__all__ = ["config", "geometry", "stats"]
