"""The two ways a preview run stops early, shared by the pipeline, operators and command line."""


class PreviewError(Exception):
    """A problem the user can fix (no camera, nothing to render, a bad setting, a missing file).

    The message is shown as is: in the operator report, the panel's status line, or on stderr
    before the command line exits non-zero.
    """


class Cancelled(Exception):
    """The user cancelled (ESC, Ctrl-C or a cancel callback); nothing was written."""


class Superseded(Cancelled):
    """A newer edit replaced a Live Update render before it finished; nothing was written."""
