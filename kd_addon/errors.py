"""The two ways a preview run stops early, shared by the pipeline, operators and command line."""


class PreviewError(Exception):
    """A problem the user can fix (no camera, nothing to render, a bad setting, a missing file).

    The message is shown as is: in the operator report, the panel's status line, or on stderr
    before the command line exits non-zero.
    """


class NoLightError(PreviewError):
    """A light mode in a scene without a light the preview can see; `why` says what the scene lacks and
    `hidden` whether it has lights the preview cannot see (a Shadow pass beside an AO render words its
    own remedy from them: engine_final)."""

    def __init__(self, message: str, why: str, hidden: bool = False):
        super().__init__(message)
        self.why, self.hidden = why, hidden

    def __reduce__(self):  # pickled whole (a process boundary), not from `args` alone
        return type(self), (str(self), self.why, self.hidden)


class Cancelled(Exception):
    """The user cancelled (ESC, Ctrl-C or a cancel callback); nothing was written."""


class Superseded(Cancelled):
    """A newer edit replaced a Live Update render before it finished; nothing was written."""
