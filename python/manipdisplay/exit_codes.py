"""Exit codes: the rows of the one table (include/manip/common/exit_codes.hpp,
docs/exit-codes.md) that manipdisplay uses. Never renumber."""
OK = 0            # ended by the participant/operator (Esc, q, window closed) or --duration
USAGE = 2         # bad command line
CONFIG = 3        # display configuration invalid or unreadable (file:line: key: reason)
OUTPUT = 6        # --stats-json / snapshot file cannot be written (exists without --force, disk full)
BACKEND = 8       # the screen cannot be opened (no X display / SDL video driver): the display's "hardware"
BUS = 10          # the LCM bus cannot be created with the given URL
INTERNAL = 70     # a bug: please report it with the message
INTERRUPTED = 130  # SIGINT/SIGTERM/SIGHUP: statistics summarised, outputs closed
