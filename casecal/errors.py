"""The one exception type a user of casecal has to know about."""


class CalibrationError(ValueError):
    """A problem the user can fix: a bad file, an unknown robot or parameter, a wrong shape.

    The message always says what was wrong and how to fix it. The command line turns it into
    one line on stderr and exit code 2.
    """


class CalibrationWarning(UserWarning):
    """Something the user should look at that does not stop the work (e.g. joint values
    outside the robot's limits). The command line prints it as one line."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, while casecal's own handler is in place: it unwinds like Ctrl-C (files in
    place are named, temporary ones removed, worker processes stopped) instead of ending
    the process where it stands."""
